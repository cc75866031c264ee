"""The command line: ``/usr/bin/python3 -m pyfem COMMAND ...`` from the repository root.

Commands:
    run SCENE.toml [--out DIR] [--set key.path=value ...] [--resume]
        Validate the scene, print the plan (as check does), then run it; results go to DIR
        (default ``runs/<scene file stem>``). With --resume, continue the interrupted run in DIR
        from its checkpoint (docs/checkpoint.md). On a terminal a progress bar shows on stderr;
        when stdout is not a terminal (a pipe, a log file) one flushed line every 5 % of the
        simulated time instead: simulated time, wall time, estimated end (pyfem.progress).
    check SCENE.toml [--set key.path=value ...]
        Validate the scene and print the plan (effects on, mesh size, dofs,
        time step and why, steps, memory and time estimates) without running.
    keys [--write [PATH]]
        Print the scene-key reference (markdown, `pyfem.scene_keys`); with --write, write it to
        PATH (default: docs/scene-keys.md of the source tree).
    bench [ARGS ...]
        Benchmarks; ARGS go to ``pyfem.bench.main`` unchanged.

A scene error (or a missing scene, mesh or record file, a mesh or record file that
cannot be read, an ``--out`` that cannot be written) prints one line ``error: ...``
on stderr and exits with status 2, with no traceback; nothing is written. What a user
may mean but is probably a mistake prints one line ``warning: ...`` on stderr each
(`Scene.warnings`; run.json keeps them under "warnings").
Ctrl-C (SIGINT) or SIGTERM during a run prints ``error: interrupted at t = ... s;
partial results kept in DIR`` and exits with 130 (SIGINT) or 143 (SIGTERM).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any, Sequence

from pyfem import __version__
from pyfem.scene import Scene, SceneError, load_scene, scene_error_from

EXIT_USAGE = 2  # argparse's own status for bad arguments; a bad scene is one too


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        # `pyfem` when run as the installed console command (pip install .).
        prog="pyfem" if Path(sys.argv[0]).name == "pyfem" else "/usr/bin/python3 -m pyfem",
        description="3D explicit seismic analysis of deep caverns in layered rock.")
    parser.add_argument("--version", action="version", version=f"pyfem {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    overrides_help = "override a scene key, e.g. --set mesh.h=2.5 --set monitor.0.point=[1,2,3]"
    run = commands.add_parser("run", help="validate and run a scene")
    run.add_argument("scene", type=Path, help="scene file (TOML)")
    run.add_argument("--out", type=Path, default=None,
                     help="run directory (default: runs/<scene file stem>)")
    run.add_argument("--set", dest="overrides", action="append", default=[],
                     metavar="KEY=VALUE", help=overrides_help)
    run.add_argument("--resume", action="store_true",
                     help="continue the interrupted run in the run directory from its checkpoint "
                          "(same scene and --set overrides; docs/checkpoint.md)")

    check = commands.add_parser("check", help="validate a scene and print the plan")
    check.add_argument("scene", type=Path, help="scene file (TOML)")
    check.add_argument("--set", dest="overrides", action="append", default=[],
                       metavar="KEY=VALUE", help=overrides_help)

    keys = commands.add_parser("keys", help="print the scene-key reference (markdown)")
    keys.add_argument("--write", nargs="?", const="", default=None, metavar="PATH",
                      help="write it to PATH instead (default: docs/scene-keys.md of the source tree)")

    view = commands.add_parser("view", help="render a run in ParaView (regions, interfaces, deformed) and "
                                            "write its ParaView state")
    view.add_argument("run_dir", type=Path, help="run directory (holds fields.xdmf and run.json)")
    view.add_argument("--time", type=float, default=None,
                      help="output time to show (s); default: that of the largest displacement")
    view.add_argument("--section-y", type=float, default=None,
                      help="y of the cut (m); default: the monitors' mean y")
    view.add_argument("--warp", type=float, default=None,
                      help="displacement magnification; default: the largest displacement as 3 %% of the model")

    commands.add_parser("bench", help="benchmarks (arguments go to pyfem.bench)",
                        add_help=False)
    return parser


def default_out_dir(scene_path: Path) -> Path:
    """The run directory used when ``--out`` is not given: ``runs/<stem>``."""
    return Path("runs") / Path(scene_path).stem


def command_run(scene_path: Path, out_dir: Path | None, overrides: Sequence[str], resume: bool = False) -> int:
    """Validate fully and hand over to ``pyfem.solver.run``, which creates `out_dir` only
    after the model and the time step are known to be good (resume: continues the interrupted
    run in `out_dir` from its checkpoint)."""
    scene = load_scene(scene_path, overrides)
    report_warnings(scene)
    out_dir = default_out_dir(scene_path) if out_dir is None else out_dir
    check_out_dir(out_dir)
    from pyfem import solver  # heavy (dolfinx, kernels): only when running
    from pyfem.progress import ProgressLines

    # Progress lines on stdout unless the bar (stderr) shows on the same terminal: under mpirun
    # stdout is a terminal and stderr a pipe, and a log would otherwise show no progress at all.
    on_terminal = sys.stdout.isatty() and sys.stderr.isatty()
    progress = None if on_terminal else ProgressLines(scene["time"]["duration"])
    summary = solver.run(scene, out_dir, on_plan=lambda plan: show_plan(scene, plan), progress=progress,
                         resume=resume)
    if not summary:  # an MPI rank other than 0: rank 0 reports
        return 0
    energy = summary["energy"]
    print(f"run finished in {summary['wall_seconds']:.1f} s: {summary['steps']} steps of "
          f"{summary['dt']:.4g} s, {summary['dofs']} dofs; energy balance error "
          f"{energy['balance_error']:.2e}")
    for name, group in summary.get("support", {}).items():
        print(f"  support {name}: {group['bolts']} {group['type']}s, peak axial force {group['peak_axial_force']:.4g} N "
              f"(yield {group['yield_force']:.4g} N), {group['yielded_segments']} of {group['segments']} segments "
              f"yielded, {group['slipping_nodes']} nodes slipped; support.csv")
    for name, peak in summary["monitors"].items():
        line = f"  {name}: peak |u| {peak['displacement']:.4g} m, |a| {peak['acceleration']:.4g} m/s^2"
        if "freefield_error" in peak:
            line += f", differs from the free field by {100 * peak['freefield_error']:.2f} %"
        print(line)
    if any("freefield_error" in peak for peak in summary["monitors"].values()):
        print("  (the difference from the free field is the error of a homogeneous model, and the "
              "scattering by the cavern, layers and interfaces otherwise)")
    motion = summary.get("input_motion")
    if motion is not None:
        print(f"  input motion (g(t) x wave.scale, as the kernel is driven): PGA {motion['pga']:.4g} m/s^2 "
              f"({motion['pga_g']:.3g} g), PGV {motion['pgv']:.4g} m/s, PGD {motion['pgd']:.4g} m; "
              f"plots/input.png")
    out = Path(out_dir)
    written = [name for name in ("run.json", "monitors/", "pairs/", "bolts/", "energy.csv", "reactions.csv", "support.csv",
                                 "support.xdmf", "static/", "plots/", "fields.xdmf") if (out / name.rstrip("/")).exists()]
    paraview = "; fields.xdmf opens in ParaView" if "fields.xdmf" in written else ""
    from pyfem.checkpoint import CHECKPOINT_NAME

    if (out / CHECKPOINT_NAME).exists():  # the final state: what extends the run
        written.append(CHECKPOINT_NAME)
        paraview += f"; {CHECKPOINT_NAME} extends the run: --resume with a longer time.duration"
    print(f"outputs: {out_dir}/ ({', '.join(written)}{paraview})")
    return 0


def command_check(scene_path: Path, overrides: Sequence[str]) -> int:
    """Validate the scene and print the solver's plan for it."""
    scene = load_scene(scene_path, overrides)
    report_warnings(scene)
    from pyfem import distributed_model  # heavy (dolfinx, kernels): only after validation

    plan = distributed_model.check(scene)  # every rank builds its part; rank 0 prints
    if plan:
        show_plan(scene, plan)
    return 0


def show_plan(scene: Scene, plan: dict) -> None:
    """Prints the plan of a scene (check, and run before it starts), flushed."""
    if any("effects" in str(key) for key in plan):
        print(f"scene: {scene.source}")
    else:  # (its first line names the scene)
        print(describe_scene(scene))
    print(format_plan(plan))
    if (scene.get("wave") or {}).get("motion", {}).get("record") is not None:
        from pyfem.seismic.setup import scene_record

        print(f"input record: {scene_record(scene).peaks_line()}")
    if "seismic_input" in scene.effects:
        print(mesh_advice(scene))
    sys.stdout.flush()


def report_warnings(scene: Scene) -> None:
    """Prints each of the scene's warnings as one ``warning: ...`` line on stderr, now and as the
    solver adds more (`Scene.warn`)."""
    def show(message: str) -> None:
        print(f"warning: {message}", file=sys.stderr)

    for message in scene.warnings:
        show(message)
    scene.on_warning = show


def check_out_dir(out_dir: Path) -> None:
    """Refuses a run directory that cannot be created or written, or that holds files of the user's
    (anything without a run's run.json, which the run would overwrite), before anything is built.

    A probe directory is made in `out_dir` (or in its nearest existing ancestor, which is where
    the run would create it) and in its parent (where an earlier run is moved aside), then
    removed: nothing is left behind.

    Raises:
        SceneError naming --out, the path and why.
    """
    import tempfile

    out_dir = Path(out_dir)

    def refuse(reason: str) -> None:
        allowed = "a directory that can be created and written"
        raise SceneError("--out", str(out_dir), allowed, f"--out {out_dir}: {reason}; allowed: {allowed}")

    if out_dir.exists() and not out_dir.is_dir():
        refuse("exists and is not a directory")
    if out_dir.is_dir() and not (out_dir / "run.json").exists():
        try:
            # Empty directories hold nothing to lose (a run stopped before its run.json leaves its
            # empty monitors/ and plots/).
            entries = sorted(entry.name for entry in out_dir.iterdir()
                             if not (entry.is_dir() and not any(entry.iterdir())))
        except OSError as error:
            refuse(f"cannot be read ({error.strerror or error})")
        if entries:
            shown = ", ".join(entries[:3]) + (", ..." if len(entries) > 3 else "")
            count = f"{len(entries)} {'entry' if len(entries) == 1 else 'entries'}"
            allowed = "a new or empty directory, or one holding an earlier run (its run.json; it is moved aside)"
            raise SceneError("--out", str(out_dir), allowed,
                             f"--out {out_dir}: holds {count} that are not a run of pyfem ({shown}), which the "
                             f"run could overwrite; nothing there was changed; allowed: {allowed}")
    ancestor = out_dir.absolute()
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        refuse(f"{ancestor} is not a directory")
    probes = [ancestor] if ancestor != out_dir.absolute() else [ancestor, ancestor.parent]
    for directory in probes:
        try:
            Path(tempfile.mkdtemp(prefix=".pyfem-probe-", dir=directory)).rmdir()
        except OSError as error:
            refuse(f"cannot create a directory in {directory} ({error.strerror or error})")


def mesh_advice(scene: Scene) -> str:
    """What the accuracy-versus-cost study says this scene's waves need (h, order) for 5 % and 1 %."""
    from pyfem.accuracy import curved_wall_size_for, element_size_for, lining_elements_for, wall_size_for

    h = scene["mesh"].get("h")
    from_file = scene["mesh"]["builder"] == "file"
    size = ("the mesh file's (measured per region under 'mesh resolution')" if from_file
            else "set by the mesh builder" if h is None else h)
    lines = [f"mesh advice (workflows/accuracy_cost.py; scene h = {size}, order {scene['mesh']['order']}):"]
    texts = {}
    for budget in (0.05, 0.01):
        try:
            # A mesh file's element family and order are its own: the advice is for them, not the cheapest.
            advice = element_size_for(scene, budget, order=scene["mesh"]["order"] if from_file else None)
            text = advice["text"].split(": ", 1)[1]
            texts.setdefault(text, []).append(budget)
        except (ValueError, FileNotFoundError) as error:
            lines.append(f"  {100 * budget:.0f} % error: no advice ({error})")
    for text, budgets in texts.items():  # one line where both budgets get the same advice
        lines.append(f"  for a {' and '.join(f'{100 * b:g} %' for b in budgets)} error: {text}")
    # A box without a static stage has no opening: no wall advice for it. A mesh file may or may not
    # have one (the scene does not say): the advice says so.
    has_opening = scene["mesh"]["builder"] != "box" or "static" in scene
    if has_opening:
        maybe = " for an opening, if the mesh has one" if scene["mesh"]["builder"] == "file" and "static" not in scene \
            else ""
        lines.append(f"wall stress advice{maybe} (workflows/wall_stress_accuracy.py: hoop stress at a circular "
                     "opening's wall against the exact dynamic answer, Pao & Mow's series):")
        for budget in (0.05, 0.01):
            try:
                advice = wall_size_for(budget)
                lines.append(f"  for a {100 * budget:g} % error: " + "; ".join(item["text"] for item in advice))
            except (ValueError, FileNotFoundError) as error:
                lines.append(f"  {100 * budget:.0f} % error: no advice ({error})")
    try:
        if not has_opening:
            raise LookupError("a box has no opening")
        sizes = {budget: curved_wall_size_for(budget) for budget in (0.05, 0.01)}
        measured = "; ".join(
            f"Q{five['order']} " + " / ".join("not reached" if a["h_over_rho"] is None else f"{a['h_over_rho']:g}"
                                              for a in (five, one))
            for five, one in zip(sizes[0.05], sizes[0.01]))
        lines.append("  a non-circular wall: read the radius as the wall's smallest radius of curvature (a static "
                     "study: an elliptical opening's excavation against the exact answer kept 5 % / 1 % with h / rho "
                     f"at most {measured}; docs/elliptical_opening.md)")
    except LookupError:
        pass
    except (ValueError, FileNotFoundError) as error:
        lines.append(f"  a non-circular wall: no advice ({error})")
    if scene.get("static", {}).get("install"):
        lines.append("lining stress advice (workflows/lining_stress_accuracy.py: the largest hoop stress read off "
                     "a bending lining's cells after the static stage against the true peak at its face; "
                     "docs/lined_tunnel.md):")
        for budget in (0.05, 0.02):
            try:
                lines.append(f"  for a {100 * budget:g} % error: {lining_elements_for(budget)['text']}")
            except (ValueError, FileNotFoundError) as error:
                lines.append(f"  {100 * budget:.0f} % error: no advice ({error})")
    return "\n".join(lines)


def command_keys(write: str | None) -> int:
    """Print the scene-key reference, or write it to `write` ("": docs/scene-keys.md of the
    source tree; an installed package has none and must be given a path)."""
    from pyfem import scene_keys

    text = scene_keys.reference()
    if write is None:
        print(text, end="")
        return 0
    path = Path(write) if write else scene_keys.repository_document()
    if path is None:
        print("error: --write: this pyfem is not in a source tree (no docs/ next to it); "
              "give a path: --write PATH", file=sys.stderr)
        return EXIT_USAGE
    try:
        path.write_text(text)
    except OSError as error:
        print(f"error: --write {path}: {error.strerror or error}; allowed: a file path that can be written",
              file=sys.stderr)
        return EXIT_USAGE
    print(f"wrote {path}")
    return 0


def command_bench(argv: Sequence[str]) -> int:
    """Pass `argv` to ``pyfem.bench.main``; its return value is the exit status."""
    from pyfem import bench

    status = bench.main(list(argv))
    return 0 if status is None else int(status)


def describe_scene(scene: Scene) -> str:
    """Title, source and effects of a validated scene, one per line."""
    effects = ", ".join(scene.effects) if scene.effects else "none (free vibration)"
    return "\n".join([
        f"scene:    {scene.source}",
        f"title:    {scene['title']}",
        f"effects:  {effects}",
    ])


# Plan keys whose entries are keyed by the scene's own names (support groups): printed as written.
NAMED_ENTRIES = ("support",)


def format_plan(plan: dict, indent: int = 0, names: bool = False) -> str:
    """A plan or summary dict as aligned ``key: value`` lines (nested dicts indented).

    Keys ending in ``bytes`` are shown in KiB/MiB/GiB, keys ending in
    ``seconds`` in s/min/h; floats with 4 significant digits. The program's keys are printed with
    spaces for underscores; the scene's names (`names`, the entries of NAMED_ENTRIES) as written.
    """
    lines = []
    width = max((len(str(k)) for k in plan), default=0) + 1
    pad = " " * indent
    for key, value in plan.items():
        label = f"{str(key) if names else str(key).replace('_', ' ')}:"
        if isinstance(value, dict):
            lines.append(f"{pad}{label}")
            lines.append(format_plan(value, indent + 2, names=not names and str(key) in NAMED_ENTRIES))
        else:
            lines.append(f"{pad}{label:<{width + 1}} {_format_value(str(key), value)}")
    return "\n".join(line for line in lines if line)


def _format_value(key: str, value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return str(value).lower() if value is not None else "-"
    if isinstance(value, (int, float)) and key.endswith("bytes"):
        size = float(value)
        for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
            if size < 1024.0 or unit == "TiB":
                return f"{size:.4g} {unit}"
            size /= 1024.0
    if isinstance(value, (int, float)) and key.endswith("seconds"):
        if value >= 3600:
            return f"{value / 3600:.3g} h"
        if value >= 60:
            return f"{value / 60:.3g} min"
        return f"{value:.3g} s"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(_format_value(key, v) for v in value) if value else "-"
    if isinstance(value, (int, str)):
        return str(value)
    try:
        return json.dumps(value)
    except TypeError:
        return str(value)


def _scene_error_text(error: SceneError, scene_path: Path | None = None) -> str:
    """The error's message, after the scene file it is about (errors found after validation,
    by the mesh builders, carry no source; --out errors are not about the scene)."""
    message = str(error)
    if error.source is None and scene_path is not None and not str(error.key).startswith("--"):
        error.source = str(scene_path)
    if error.source and not message.startswith(error.source):
        message = f"{error.source}: {message}"
    return message


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``/usr/bin/python3 -m pyfem``; returns the exit status. Under ``mpirun -n N`` every
    rank runs it and rank 0 speaks (pyfem/distributed_model.py): the others' lines are the same or
    nothing, except a failure of their own, whose traceback they print."""
    from pyfem.ranks import launched_rank

    if launched_rank() > 0:
        import contextlib

        with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet), contextlib.redirect_stderr(quiet):
            try:
                return _main(argv)
            except SystemExit:  # argparse's usage errors and --help: rank 0 has said it
                raise
            except BaseException:
                import traceback

                traceback.print_exc(file=sys.__stderr__)
                raise
    return _main(argv)


def _main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "bench":
        # bench owns its arguments; argparse would reject its options.
        return command_bench(argv[1:])
    args = _parser().parse_args(argv)
    if args.command == "keys":
        return command_keys(args.write)
    if args.command == "view":
        return command_view(args.run_dir, args.time, args.section_y, args.warp)
    try:
        if args.command == "run":
            return command_run(args.scene, args.out, args.overrides, args.resume)
        return command_check(args.scene, args.overrides)
    except SceneError as error:
        print(f"error: {_scene_error_text(error, args.scene)}", file=sys.stderr)
        return EXIT_USAGE
    except ValueError as error:
        # Builders and readers below the scene (pyfem.geometry, pyfem.interfaces, ...) report bad
        # input as a ValueError whose message starts with the scene key; any other is a bug.
        converted = scene_error_from(error)
        if converted is None:
            raise
        print(f"error: {_scene_error_text(converted, args.scene)}", file=sys.stderr)
        return EXIT_USAGE
    except FileNotFoundError as error:
        name = error.filename if error.filename is not None else str(error)
        print(f"error: no such file: {name}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as error:
        print(f"error: {interruption_text(error)}", file=sys.stderr)
        return getattr(error, "exit_status", 130)


def command_view(run_dir: Path, time: float | None, section_y: float | None, warp: float | None) -> int:
    """Render a run with ParaView's pvbatch (pyfem/pvbatch_view.py; under xvfb-run when there is no
    X display): plots/paraview.png and paraview.pvsm in the run directory (docs/paraview.md)."""
    import shutil
    import subprocess

    run_dir = Path(run_dir)
    for name in ("run.json", "fields.xdmf"):
        if not (run_dir / name).exists():
            print(f"error: view: {run_dir / name} does not exist; allowed: a run directory with fields "
                  f"(output.xdmf_interval > 0)", file=sys.stderr)
            return EXIT_USAGE
    pvbatch = shutil.which("pvbatch")
    if pvbatch is None:
        print("error: view: pvbatch not found; install Debian's paraview and python3-paraview "
              "(scripts/setup.sh --with-paraview)", file=sys.stderr)
        return EXIT_USAGE
    command = [pvbatch, str(Path(__file__).with_name("pvbatch_view.py")), str(run_dir)]
    for flag, value in (("--time", time), ("--section-y", section_y), ("--warp", warp)):
        if value is not None:
            command += [flag, repr(value)]
    if not os.environ.get("DISPLAY"):
        xvfb_run = shutil.which("xvfb-run")
        if xvfb_run is None:
            print("error: view: no X display and no xvfb-run; install Debian's xvfb", file=sys.stderr)
            return EXIT_USAGE
        command = [xvfb_run, "-a"] + command
    # Xvfb started by xvfb-run is sometimes gone when pvbatch opens its window on a busy machine
    # ("bad X server connection"): try that case again, nothing else.
    for _ in range(4):
        result = subprocess.run(command, capture_output=True, text=True)
        if result.returncode == 0 or "bad X server connection" not in result.stderr:
            break
    if result.returncode == EXIT_USAGE:
        # The script's own one-line refusal (e.g. fields.xdmf without displacement).
        lines = [line for line in result.stderr.splitlines() if line.startswith("error:")]
        print(f"error: view: {lines[-1].removeprefix('error: ')}" if lines else
              "error: view: the run's fields cannot be shown", file=sys.stderr)
        return EXIT_USAGE
    if result.returncode != 0:
        print(result.stderr.strip()[-2000:], file=sys.stderr)
        print(f"error: view: pvbatch failed with exit status {result.returncode}", file=sys.stderr)
        return 1
    line = next((text for text in result.stdout.splitlines() if text.startswith("PARAVIEW ")), None)
    if line is None:
        print("error: view: pvbatch wrote no picture", file=sys.stderr)
        return 1
    shown = json.loads(line.removeprefix("PARAVIEW "))
    print(f"view: t = {shown['time']:g} s (largest displacement {shown['shown_displacement']:.4g} m, drawn "
          f"x{shown['warp']:.3g}), regions {', '.join(shown['regions'])}"
          + (", interfaces coloured by slip" if shown["interfaces"] else ""))
    print(f"  picture {shown['png']}")
    print(f"  ParaView state {shown['state']} (File > Load State, search files under the run directory)")
    return 0


def interruption_text(error: KeyboardInterrupt) -> str:
    """One line on an interrupted command: when it stopped and where its partial results are."""
    if not hasattr(error, "out_dir"):  # not from a run (pyfem.interrupts.RunInterrupted)
        return "interrupted"
    reached, out_dir = error.time_reached, error.out_dir
    if out_dir is None:
        seconds = getattr(error, "setup_seconds", None)
        if seconds is not None:
            return (f"interrupted in the set-up ({error.setup_words}) after {seconds:.0f} s, before the run "
                    "started; nothing written, and the next run does the set-up again")
        return "interrupted before the run started; nothing written"
    if reached is None:
        return f"interrupted before the first sample; run.json in {out_dir} says so"
    from pyfem.checkpoint import CHECKPOINT_NAME

    if (Path(out_dir) / CHECKPOINT_NAME).exists():
        return (f"interrupted at t = {reached:.6g} s; partial results and a checkpoint kept in {out_dir} "
                f"(continue with the same command and --resume)")
    return f"interrupted at t = {reached:.6g} s; partial results kept in {out_dir}"
