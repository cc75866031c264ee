"""Names of the static stage's outputs in the run directory (docs/static.md), written by the model's
stage (pyfem/distributed_stage.py, pyfem/distributed_model.py):

    static/static.json   the stages (what each removed, installed and loaded; solver, iterations,
                         residual, time, largest displacement), the boundary during the stage and its
                         support forces, the hand-over's out-of-balance, displacement and stress at
                         the monitors, the contact pairs' static forces in figures
    static/fields.xdmf   (+ .h5) one time per stage (t = 1: after stage 1, t = 2: after stage 2)
    static/section_stress.png, static/interface_stress.png (with contact): pyfem/static_plots.py
    static/support.png, static/support.xdmf (+ .h5) with static.support (pyfem/support_output.py)
    static/hand_over.npz what `--resume` takes instead of solving a relaxed stage again
"""
from __future__ import annotations

# Monitor stress names of monitors/NAME.csv and their tensor components.
VOIGT_NAMES = {"sxx": (0, 0), "syy": (1, 1), "szz": (2, 2), "sxy": (0, 1), "syz": (1, 2), "sxz": (0, 2)}

# rank 0's record of a relaxed stage's hand-over (static/), naming the ranks' files
HAND_OVER_NAME = "hand_over.npz"
