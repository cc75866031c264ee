"""The static stage's excavation steps as the scene gives them (docs/static.md): `[[static.step]]`
entries, or the one-step form's keys. A leaf module: pyfem/scene.py validates the keys, pyfem/mesh.py
builds the model without the regions `model_excavation` names."""
from __future__ import annotations

from typing import Mapping

ONE_STEP_KEYS = ("excavate", "relaxation", "install", "support")
"""The one-step form's keys of [static], and the keys of each [[static.step]] entry."""


def static_steps(static: Mapping) -> list[dict]:
    """The stage's steps, each with ONE_STEP_KEYS: the [[static.step]] entries, or the one-step form's."""
    if static.get("step"):
        return [dict(step) for step in static["step"]]
    return [{key: static[key] for key in ONE_STEP_KEYS}]


def model_excavation(scene: Mapping, stage_model: bool = False) -> list[str]:
    """The regions the model is built without (pyfem/mesh.py): static.excavate, or with
    [[static.step]] every step's (the dynamic run's model); `stage_model`: the first step's only
    (the sequence's model, pyfem/distributed_sequence.py)."""
    static = scene.get("static") or {}
    steps = static_steps(static) if static else []
    if stage_model:
        steps = steps[:1]
    return [name for step in steps for name in step["excavate"]]
