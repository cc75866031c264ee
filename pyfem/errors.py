"""The error every scene check raises: one line naming the key, the value and what is allowed.

It lives apart from pyfem.scene so that the modules that read a scene's mesh, interfaces and
checkpoints can raise it without importing the scene's validation (which imports them).
"""
from __future__ import annotations

import json
from typing import Any


class SceneError(ValueError):
    """A scene key with a missing, unknown, mistyped or out-of-range value.

    Attributes:
        key: Dotted path of the offending key (``"materials.rock.nu"``,
            ``"monitor.0.point"``); ``None`` when the problem is not one key
            (a file that is not TOML).
        value: The value found (``None`` when missing).
        allowed: What would have been accepted, in words.
        source: The scene file (or ``"<dict>"``), set by `load_scene`/`parse_scene`.
    """

    def __init__(self, key: str | None, value: Any, allowed: str, message: str | None = None):
        self.key = key
        self.value = value
        self.allowed = allowed
        self.source: str | None = None
        if message is None:
            message = f"scene key '{key}' = {_show(value)}: {allowed}"
        super().__init__(message)


def _show(value: Any) -> str:
    """A value as it would be written in TOML (strings double-quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_show(v)}" for k, v in value.items()) + "}"
    return repr(value)
