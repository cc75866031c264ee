"""Issue 51: static.json and run.json are strict JSON (no NaN), and interface_stress.png's title fits."""
import json

import numpy as np

TRIAL_TITLE = "powerhouse + transformer hall, 70 deg bedding plane, oblique SV El Centro"


def strict_loads(text):
    def refuse(name):
        raise ValueError(f"not strict JSON: {name}")
    return json.loads(text, parse_constant=refuse)


def test_interface_means_without_near_pairs_are_null_and_the_json_is_strict(tmp_path):
    """No pair within near_wall of the wall (the trial's 37 pairs, 0 near): the means are None, and the
    writer of static.json and run.json (pyfem.output._write_json) writes null for them and for any
    other non-finite number."""
    from pyfem.output import _write_json
    from pyfem.static_plots import interface_stress

    coords = np.array([[10.0 + k, 0.0, 0.0] for k in range(5)])
    normal = np.tile([0.0, 0.0, 1.0], (5, 1))
    area = np.ones(5)
    before = np.tile([0.0, 0.0, -2.0e6], (5, 1))
    figure = interface_stress(tmp_path / "interface_stress.png", coords, normal, area, before, 0.5 * before,
                              np.zeros((1, 3)), TRIAL_TITLE, near_wall=2.0)
    assert (tmp_path / "interface_stress.png").stat().st_size > 5_000
    assert figure["pairs"] == 5 and figure["pairs_near_wall"] == 0
    assert figure["before_mean"] is None and figure["after_mean"] is None
    report = {"plots": {"interface_stress": figure}, "nan": np.float64("nan"), "inf": float("inf"),
              "values": np.array([1.5, np.nan, -np.inf]), "count": np.int64(3), "flag": np.bool_(True)}
    path = tmp_path / "static.json"
    _write_json(path, report)
    text = path.read_text()
    assert "NaN" in json.dumps(report, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
    back = strict_loads(text)
    assert back["plots"]["interface_stress"] == {"near_wall": 2.0, "pairs": 5, "pairs_near_wall": 0,
                                                 "before_mean": None, "after_mean": None}
    assert back["nan"] is None and back["inf"] is None and back["values"] == [1.5, None, None]
    assert back["count"] == 3 and back["flag"] is True


def test_a_long_title_fits_the_interface_figure():
    """The trial's title plus " interface normal stress" overflows the 7 in figure on one line; wrapped
    by fit_title it lies inside the figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pyfem.static_plots import fit_title

    text = f"{TRIAL_TITLE} interface normal stress"
    widths = {}
    for name in ("plain", "fitted"):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        if name == "plain":
            ax.set_title(text, fontsize=10)
        else:
            fit_title(ax, text)
        fig.tight_layout()
        fig.canvas.draw()
        box = ax.title.get_window_extent(fig.canvas.get_renderer())
        widths[name] = (box.x0, box.x1, box.y1, fig.bbox.width, fig.bbox.height)
        plt.close(fig)
    x0, x1, y1, width, height = widths["plain"]
    assert x0 < 0 or x1 > width, "the unwrapped title overflows (else this test shows nothing)"
    x0, x1, y1, width, height = widths["fitted"]
    assert 0 <= x0 and x1 <= width and y1 <= height
