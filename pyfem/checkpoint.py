"""Checkpoint and resume of a run (docs/checkpoint.md): what every rank count shares.

A checkpoint is the complete state of a run at one sample, written by the model
(pyfem/distributed_model.py `DistributedRun.write_checkpoint`): each rank's u, v, a and kernel state
(`save_state`: energy account, last internal force, contact pairs, every material point) keyed by
position in `checkpoint.ID.rankR.npz`, and rank 0's record `checkpoint.npz` (the fingerprint, t, the
samples so far, the history files' lengths), written last and atomically (`write_atomically`: a
temporary file, fsync, rename) every `[output] checkpoint_interval` seconds of wall time, when the
run is interrupted (Ctrl-C, SIGTERM) and at the end: a finished run keeps its final state (meta
"final"), so that it can be extended to a longer time.duration.

`/usr/bin/python3 -m pyfem run SCENE --out DIR --resume` (on any rank count) rebuilds the model from the
scene, checks that it is the model of the checkpoint (`Checkpoint.check_scene`, then the model's
dofs, dt and levels), truncates the histories and fields to the checkpoint's sample and continues:
the histories of a resumed run equal those of an uninterrupted one bit for bit (tests/test_checkpoint.py).
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pyfem.errors import SceneError

CHECKPOINT_NAME = "checkpoint.npz"
FORMAT = 1  # bumped when the content changes; an older checkpoint is refused, not misread
# Scene keys a resumed run may change: they do not alter the computed state.
# time.duration: an interrupted run may be continued to a later (or an earlier, not yet reached) end.
RESUMABLE_CHANGES = (("output", "checkpoint_interval"), ("time", "duration"))

# Keys added after checkpoints were first written, with the value that reproduces the run before
# they existed: left out of the fingerprint at that value, so an earlier run's checkpoint still
# continues (a run that sets another value is another model).
# A key's path through the scene's tables; "*" stands for every table at that depth (materials.NAME).
LATER_KEYS = ((("time", "matrix_precision"), "double"),
              (("materials", "*", "plasticity", "integration"), "full"),
              (("materials", "*", "damage", "integration"), "full"),
              (("wave", "motion", "record", "scale"), "after_filter"))

# Keys left out of the scene's fingerprint whatever their value, because the model's part holds what
# they decide: time.local_stepping (true, false or "auto", which decides on the model) by dt, steps
# and the levels' hash, so that a run resumes under any setting that steps it the same way.
DECIDED_KEYS = (("time", "local_stepping"),)


# The scene's file keys (resolved to absolute paths by the scene): a checkpoint holds a hash of
# each file's content, not its path, so a run continues from another clone or a moved project.
FILE_KEYS = (("mesh", "file"), ("wave", "motion", "record", "file"))


def _file_content(path) -> str:
    """'sha256:<hex>' of a file's bytes, or the path itself when it cannot be read."""
    try:
        status = os.stat(path)
    except OSError:
        return str(path)
    return _hash_file(str(path), status.st_mtime_ns, status.st_size)


@functools.lru_cache(maxsize=16)
def _hash_file(path: str, mtime_ns: int, size: int) -> str:
    """The hash of a file's bytes, once per (path, modification time, size): every checkpoint
    repeats the fingerprint."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 22), b""):
            digest.update(block)
    return "sha256:" + digest.hexdigest()


def scene_fingerprint(scene) -> dict:
    """The scene part of the fingerprint: its JSON without the keys a resume may change
    (RESUMABLE_CHANGES), without later keys at their old behaviour (LATER_KEYS), files by content."""
    data = scene.to_json()
    for table, key in RESUMABLE_CHANGES:
        data.get(table, {}).pop(key, None)
    for path, old_behaviour in LATER_KEYS:
        for table in _tables_at(data, path[:-1]):
            if path[-1] in table and table[path[-1]] == old_behaviour:
                table.pop(path[-1])
    _drop_decided(data)
    return _files_by_content(data)


def _drop_decided(scene_json: dict) -> None:
    """`scene_json` without the DECIDED_KEYS (in place)."""
    for path in DECIDED_KEYS:
        for table in _tables_at(scene_json, path[:-1]):
            table.pop(path[-1], None)


def _tables_at(data: dict, path: tuple) -> list:
    """The tables (dicts) of `data` at `path`, "*" matching every key at its depth."""
    tables = [data]
    for name in path:
        tables = [value for table in tables
                  for value in (table.values() if name == "*" else [table.get(name)]) if isinstance(value, dict)]
    return tables


def _files_by_content(scene_json: dict) -> dict:
    """`scene_json` with each FILE_KEYS path replaced by the hash of its file (in place; a value
    that is a hash already is kept)."""
    for keys in FILE_KEYS:
        holder = scene_json
        for key in keys[:-1]:
            holder = holder.get(key) if isinstance(holder, dict) else None
        value = holder.get(keys[-1]) if isinstance(holder, dict) else None
        if isinstance(value, str) and not value.startswith("sha256:"):
            holder[keys[-1]] = _file_content(value)
    return scene_json


def input_follows_duration(scene) -> bool:
    """Whether the input motion depends on time.duration: a Ricker wavelet through [[wave.layers]], whose
    layered free field is computed by FFT over the run's time (a record's covers the whole record).
    Measured on workflows/scenes/layered_site_sv30.toml: run to 0.3 s and extended to 0.6 s, the
    monitors differed from the 0.6 s run's by up to 0.75 % of their largest value."""
    wave = scene.get("wave") or {}
    return bool(wave.get("layers")) and (wave.get("motion") or {}).get("ricker") is not None


def _differences(saved, current, path: str = ""):
    """Yields (key path, saved value, current value) for every leaf where two JSON values differ
    (a key on one side only: the other value is None)."""
    if isinstance(saved, dict) and isinstance(current, dict):
        for key in sorted(set(saved) | set(current)):
            where = f"{path}.{key}" if path else str(key)
            if key not in saved or key not in current:
                yield where, saved.get(key), current.get(key)
            else:
                yield from _differences(saved[key], current[key], where)
    elif isinstance(saved, list) and isinstance(current, list) and len(saved) == len(current):
        for index, (a, b) in enumerate(zip(saved, current)):
            yield from _differences(a, b, f"{path}.{index}")
    elif saved != current:
        yield path or "(value)", saved, current


def _scene_difference_text(saved: dict, current: dict, shown: int = 3) -> str | None:
    """One clause for a refused resume: another scene (its title differs), or the first `shown`
    keys whose values differ, each with the scene's and the checkpoint's value; None when equal.
    Defaults and derived values are part of the fingerprint, so a changed key may show together with
    the keys that follow it (contact.dynamic_friction_angle with contact.friction_angle)."""
    found = list(_differences(saved, current))
    if not found:
        return None
    if saved.get("title") != current.get("title"):
        return (f"the checkpoint is of another scene (title {saved.get('title')!r}; this scene's is "
                f"{current.get('title')!r}; {len(found)} keys differ)")

    def short(value) -> str:
        text = json.dumps(value)
        return text if len(text) <= 40 else text[:37] + "..."

    listed = "; ".join(f"{key} = {short(now)} (the checkpoint's: {short(then)})" for key, then, now in found[:shown])
    more = f"; and {len(found) - shown} more" if len(found) > shown else ""
    return f"the scene differs from the checkpoint's: {listed}{more}"


def _first_difference(saved, current) -> str | None:
    """The first key path (dotted) where two JSON values differ, None when equal."""
    return next((where for where, _, _ in _differences(saved, current)), None)


@dataclass
class Checkpoint:
    """A checkpoint read back: the run's state at one sample.

    Attributes:
        path: the file.
        meta: JSON part: fingerprint, t, outputs_done (samples after t = 0), timing, the writer's.
        u, v, a: (3 n_nodes,) displacement (m), velocity (m/s), acceleration (m/s^2).
        kernel: `Stepper.save_state` blocks (name -> bytes).
        writer: arrays of the writer (samples so far), see RunWriter.checkpoint_state.
    """

    path: Path
    meta: dict
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    kernel: dict = field(default_factory=dict)
    writer: dict = field(default_factory=dict)

    @property
    def t(self) -> float:
        return float(self.meta["t"])

    @property
    def outputs_done(self) -> int:
        return int(self.meta["outputs_done"])

    def saved_fingerprint(self) -> dict:
        """The checkpoint's fingerprint, its scene's files by content (a checkpoint written before
        FILE_KEYS held their paths: hashed now, from the path it names, if that file still exists)."""
        saved = json.loads(json.dumps(self.meta["fingerprint"]))  # a copy
        _files_by_content(saved.get("scene", {}))
        _drop_decided(saved.get("scene", {}))  # written before they were left out
        return saved

    def check_scene(self, scene) -> None:
        """Raises SceneError (key --resume) when this checkpoint is not of `scene`: checked before
        the model is built (and a static stage solved), so another scene is refused at once."""
        self._refuse(_scene_difference_text(self.saved_fingerprint()["scene"], scene_fingerprint(scene)))

    def check_model(self, ours: dict, scene, end: float) -> None:
        """Refuses (SceneError, key --resume, on every rank alike) a checkpoint of another model: `ours`
        is this model's fingerprint (pyfem.distributed_model.DistributedRun._fingerprint: dofs, dt,
        steps, levels, time_origin, deterioration), `end` the time its run ends at. The steps are not
        compared (a resume may change time.duration) unless the input follows the duration."""
        theirs = self.meta["fingerprint"]
        if "steps" in theirs and theirs["steps"] != ours["steps"]:
            self.check_input_follows(scene)
        self.refuse_other_stepping(theirs.get("levels") is not None, ours.get("levels") is not None)
        for key in ("dofs", "dt", "levels"):
            if theirs.get(key) != ours.get(key):
                self._refuse(f"the model's {key} differs from the checkpoint's (another mesh or build?)")
        if theirs.get("deterioration") != ours.get("deterioration"):
            self._refuse_difference(_first_difference({"deterioration": theirs.get("deterioration")},
                                                      {"deterioration": ours.get("deterioration")}))
        if theirs.get("time_origin", 0.0) != ours["time_origin"]:
            self._refuse("the checkpoint was written before record time became run time (its record's lead-in "
                         "ran from t = 0, now it runs at t < 0): start the run again")
        self.check_end(end, scene["time"]["duration"])

    @property
    def final(self) -> bool:
        """Whether this is a finished run's final state (written at its last sample)."""
        return bool(self.meta.get("final"))

    def check_end(self, end: float, duration: float) -> None:
        """Refuses (SceneError, key --resume) a time.duration that ends before the checkpoint's time,
        and for a finished run's final state one that does not end after it (nothing to continue)."""
        t = float(self.meta["t"])
        tolerance = 1e-9 * max(abs(end), 1.0)
        if self.final and t >= end - tolerance:
            raise SceneError("time.duration", duration, f"more than the finished run's {t:.6g} s",
                             f"--resume {self.path.parent}: the run finished at t = {t:.6g} s; time.duration = "
                             f"{duration:g} s {'ends before' if t > end + tolerance else 'adds nothing to'} it: "
                             f"give a longer time.duration (--set time.duration=...) to extend the run")
        if t > end + tolerance:
            self._refuse(f"time.duration = {duration:g} s ends before the checkpoint's t = {t:.6g} s: give at least "
                         f"{t:.6g} s to continue the run")

    def check_input_follows(self, scene) -> None:
        """Refuses (SceneError, key time.duration) another duration where the input motion depends on
        it (`input_follows_duration`): the part already run had another input."""
        if input_follows_duration(scene):
            raise SceneError("time.duration", scene["time"]["duration"], "the duration of the checkpoint's run",
                             f"--resume {self.path.parent}: with [[wave.layers]] and a Ricker wavelet the layered free "
                             f"field is computed over the run's time (time.duration), so time.duration = "
                             f"{scene['time']['duration']:g} s is another input than the run's: run the longer "
                             f"duration from the start (without --resume)")

    def refuse_other_stepping(self, stepped_locally: bool, steps_locally: bool) -> None:
        """Refuses (SceneError, key --resume) a resume that would step globally where the interrupted
        run stepped locally (time.local_stepping), or the other way round."""
        if stepped_locally != steps_locally:
            stepped = "locally" if stepped_locally else "globally"
            self._refuse(f"the interrupted run stepped {stepped} (time.local_stepping) and this one would not; "
                         f"set time.local_stepping = {'true' if stepped_locally else 'false'} to resume it")

    def _refuse_difference(self, where: str | None) -> None:
        if where is None:
            return
        if where.startswith("deterioration.2"):  # (R0, lambda, t_s, ...): t_s alone, time.duration's without a record
            self._refuse("the interfaces' wear time t_s differs from the checkpoint's: without a record t_s is "
                         "time.duration (contact.deterioration), so another time.duration is another model "
                         "and cannot continue this run")
        if where.startswith("deterioration"):
            self._refuse("the interfaces' deterioration differs from the checkpoint's (a checkpoint written before "
                         "2026-11-27 ran the wear's clock from the run's start, lead-in included; now it starts "
                         "with the record's window)")
        if where.startswith("scene."):
            self._refuse(f"the scene's {where[len('scene.'):]} differs from the checkpoint's")
        else:
            self._refuse(f"the model's {where} differs from the checkpoint's (another mesh or build?)")

    def _refuse(self, reason: str | None) -> None:
        if reason is None:
            return
        raise SceneError("--resume", str(self.path), "the checkpoint of this scene's run",
                         f"--resume {self.path}: {reason}; resume with the scene and --set "
                         f"overrides of the interrupted run, or start a new run without --resume")


def write_atomically(path: Path, arrays: dict) -> Path:
    """np.savez of `arrays` to `path` through a temporary file, synced, then renamed: a crash
    leaves the old file or the new one, never a part."""
    path = Path(path)
    temporary = path.with_name(path.name + ".tmp")
    with open(temporary, "wb") as handle:
        np.savez(handle, **arrays)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(temporary, path)
    directory = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(directory)  # the rename itself survives a crash
    finally:
        os.close(directory)
    return path


def read_checkpoint(out_dir, state: bool = True) -> Checkpoint:
    """Reads `checkpoint.npz` of a run directory.

    Args:
        out_dir: the run directory.
        state: False reads the JSON part only (t, fingerprint; u, v, a None, no kernel or writer
            arrays): np.load reads an .npz member only when asked for it, so this costs the meta's
            bytes, not the state's (184 MB on the paper-scale case).

    Raises:
        SceneError (key --resume) for a missing, unreadable or other-format checkpoint, or a run
        that finished.
    """
    out_dir = Path(out_dir)
    path = out_dir / CHECKPOINT_NAME
    allowed = "a run directory holding the checkpoint of an unfinished run"

    def refuse(reason: str):
        raise SceneError("--resume", str(out_dir), allowed, f"--resume: {out_dir}: {reason}; allowed: {allowed}")

    if not path.exists():
        status = None
        try:
            status = json.loads((out_dir / "run.json").read_text()).get("status")
        except (OSError, ValueError):
            pass
        if status == "finished":
            refuse(f"the run finished without keeping its final state ({CHECKPOINT_NAME}); there is nothing to "
                   "continue from")
        refuse(f"no {CHECKPOINT_NAME} (the run stopped before its first checkpoint, "
               f"or output.checkpoint_interval was 0)" if out_dir.exists() else "no such directory")
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(bytes(data["meta"]).decode())
            if meta.get("format") != FORMAT:
                refuse(f"{CHECKPOINT_NAME} has format {meta.get('format')}, this pyfem reads {FORMAT}")
            if not state:
                return Checkpoint(path=path, meta=meta, u=None, v=None, a=None)
            if meta.get("model") != "distributed":  # the serial path's layout of an earlier version
                refuse(f"{CHECKPOINT_NAME} was written by the serial path of an earlier version (its state in one "
                       "file), which this version no longer has; run the scene again")
            return _joined_rank_states(path, meta, data)  # each rank's state is in its own file
    except SceneError:
        raise
    except (OSError, ValueError, KeyError) as error:
        refuse(f"{CHECKPOINT_NAME} cannot be read ({type(error).__name__}: {error})")


def rank_file_name(identifier: int, rank: int) -> str:
    """The file of one rank's state in a distributed run's checkpoint `identifier`
    (pyfem/distributed_model.py; `checkpoint.npz` names the identifier and the rank count)."""
    return f"checkpoint.{identifier}.rank{rank}.npz"


def _joined_rank_states(path: Path, meta: dict, data) -> Checkpoint:
    """A distributed run's checkpoint read whole (any rank count, one included): u, v, a of every
    rank's owned nodes in rank order, `kernel` each other block of the rank files joined in rank order
    (its bytes: the pairs' and cells' states keyed by position, "pairs/effective_normal", ...), `writer`
    the run's samples (`checkpoint.npz`'s writer_ arrays without the prefix)."""
    files = [path.with_name(rank_file_name(int(meta["id"]), rank)) for rank in range(int(meta["fingerprint"]["ranks"]))]
    blocks: dict = {}
    for name in files:
        with np.load(name, allow_pickle=False) as rank:
            for key in rank.files:
                blocks.setdefault(key, []).append(np.array(rank[key]))
    joined = {key: np.concatenate([np.atleast_1d(x) for x in parts]) for key, parts in blocks.items()}
    writer = {key.removeprefix("writer_"): np.array(data[key]) for key in data.files if key.startswith("writer_")}
    u, v, a = (joined.pop(x) for x in "uva")
    kernel = {key: np.ascontiguousarray(value).tobytes() for key, value in joined.items()}
    return Checkpoint(path=path, meta=meta, u=u, v=v, a=a, kernel=kernel, writer=writer)


def interrupted_run(out_dir) -> bool:
    """Whether `out_dir` holds the checkpoint of a run that stopped before its end (not a finished
    run's final state): what a workflow resumes without being asked to extend a run."""
    if not (Path(out_dir) / CHECKPOINT_NAME).exists():
        return False
    try:
        return not read_checkpoint(out_dir, state=False).final
    except SceneError:
        return False


class CheckpointClock:
    """When the next periodic checkpoint is due: every `interval` seconds of wall time (0: never).

    The clock may start with time already on it: a run's set-up (the mesh, the static stage, the
    local-stepping map's check: half an hour for the paper-scale case study) counts towards the
    first interval, so a run whose set-up took longer than the interval writes its first
    checkpoint at its first sample, and a run stopped soon after its set-up resumes from there
    instead of solving its stage again.

    Args:
        interval: seconds of wall time between checkpoints (`[output] checkpoint_interval`).
        elapsed: seconds of wall time already spent before the clock starts (the set-up).
    """

    def __init__(self, interval: float, elapsed: float = 0.0):
        self.interval = float(interval)
        self._last = time.monotonic() - max(float(elapsed), 0.0)
        self.count = 0
        self.seconds = 0.0  # wall time spent writing checkpoints

    def due(self) -> bool:
        return self.interval > 0 and time.monotonic() - self._last >= self.interval

    def written(self, seconds: float) -> None:
        """Records one checkpoint that took `seconds`; the next is due an interval from now."""
        self.count += 1
        self.seconds += seconds
        self._last = time.monotonic()
