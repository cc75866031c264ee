"""The documents name only things that exist: README.md, CHANGELOG.md and docs/*.md.

- Every repository file path they name exists: a path under one of the repository's top-level
  folders (`pyfem/operators.py`, `workflows/results/strong_scaling.json`, ...) and every relative
  markdown link target (`[static.md](static.md)`, relative to the document).
- Every `pyfem.` module they name exists as a file of the package, and a name after it
  (`pyfem.solver.make_stepper`) is defined at the top level of that module (for the compiled
  `pyfem._kernels`: an attribute of it). Deeper names (methods) are not checked.
- Every scene key they name in backticks exists in the key registry (`pyfem.scene_keys`, the
  schema that `python3 -m pyfem keys` prints): dotted keys (`wave.surface`, `time.duration=2.0`
  as in `--set`, `materials.sandstone.plasticity`: any name for a named table, any index for an
  array of tables), and table forms (`[static]`, `[[wave.component]]`, `[static] relaxation`).

Loose on purpose: a backticked dotted word counts as a scene key only if its first part is a
top-level table of the schema and it is not a file name (`static.json`); a backticked `[table]`
always counts; prose is never read as a path unless it starts with a top-level folder.
"""
import ast
import pathlib
import re

import pytest

from pyfem import scene_keys
from pyfem.scene import FreeTable

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DOCUMENTS = [REPOSITORY / "README.md", REPOSITORY / "CHANGELOG.md"] + sorted((REPOSITORY / "docs").glob("*.md"))
TOP_FOLDERS = sorted(path.name for path in REPOSITORY.iterdir()
                     if path.is_dir() and not path.name.startswith(".")
                     and path.name not in {"build", "runs", "__pycache__"})
# Keys a document may name although no scene accepts them, by document (none today).
KNOWN_UNKNOWN_KEYS: dict[str, set[str]] = {}
FILE_SUFFIXES = ("json", "csv", "png", "npz", "xdmf", "h5", "md", "py", "toml", "msh", "geo", "txt",
                 "pvsm", "log", "so", "cpp", "hpp")


def _ids(paths):
    return [path.relative_to(REPOSITORY).as_posix() for path in paths]


# --- repository paths ------------------------------------------------------------------------------

_PATH = re.compile(r"(?<![\w/.$~-])((?:%s)/[\w./-]*[\w/])([*{]?)" % "|".join(map(re.escape, TOP_FOLDERS)))
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def _exists(path: pathlib.Path) -> bool:
    # A module may be named without its suffix (pyfem/_kernels: the built .so).
    return path.exists() or bool(list(path.parent.glob(path.name + ".*")))


def named_paths(document: pathlib.Path) -> list[str]:
    """The repository paths a document names that do not exist."""
    text = document.read_text()
    missing = set()
    for path, wildcard in _PATH.findall(text):
        if wildcard:  # a pattern (workflows/scenes/case1_*.toml, ..._{coarse,paper}.toml): something matches
            if not list(REPOSITORY.glob(path + "*")):
                missing.add(path + wildcard)
        elif not _exists(REPOSITORY / path.rstrip("/")):
            missing.add(path)
    for target in _LINK.findall(text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        target = target.split("#")[0]
        if target and not _exists((document.parent / target).resolve()):
            missing.add(target)
    return sorted(missing)


# --- pyfem modules -----------------------------------------------------------------------------------

_MODULE = re.compile(r"(?<![\w/.])pyfem((?:\.[A-Za-z_]\w*)+)")


def _module_file(parts: list[str]) -> pathlib.Path | None:
    base = REPOSITORY / "pyfem" / pathlib.Path(*parts) if parts else REPOSITORY / "pyfem"
    if base.with_suffix(".py").is_file():
        return base.with_suffix(".py")
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    if parts and list(base.parent.glob(base.name + ".*.so")):
        return base  # the compiled kernel
    return None


def _top_level_names(source: pathlib.Path) -> set[str]:
    if source.suffix != ".py":  # the compiled kernel: its attributes
        from pyfem import _kernels

        return set(dir(_kernels))
    names = set()
    for node in ast.parse(source.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                names |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(alias.asname or alias.name).split(".")[0] for alias in node.names}
    if source.name == "__init__.py":  # a package's sub-modules
        names |= {p.stem for p in source.parent.glob("*.py")} | {p.name for p in source.parent.iterdir() if p.is_dir()}
    return names


def unknown_modules(document: pathlib.Path) -> list[str]:
    """The `pyfem.` names a document gives that are neither a module nor a name in one."""
    unknown = set()
    for dotted in set(_MODULE.findall(document.read_text())):
        parts = dotted.strip(".").split(".")
        # the longest prefix that is a module of the package, then one name defined in it
        for n in range(len(parts), 0, -1):
            source = _module_file(parts[:n])
            if source is not None:
                rest = parts[n:]
                if rest and rest[0] not in _top_level_names(source):
                    unknown.add("pyfem." + ".".join(parts[:n + 1]))
                break
        else:
            unknown.add("pyfem." + parts[0])
    return sorted(unknown)


# --- scene keys ----------------------------------------------------------------------------------------

SPECS = scene_keys.key_specs()
TABLES = {path for path, _ in scene_keys.tables() if path}
ROOTS = {key.split(".")[0] for key in SPECS}
_CODE = re.compile(r"`([^`\n]+)`")
_DOTTED = re.compile(r"^([a-z_]+(?:\.[\w]+)+)(?:\s*=.*)?$")
_TABLE_FORM = re.compile(r"^\[\[?([a-z_][\w.]*)\]\]?(?: (\w+))?(?:\s*=.*)?$")


def _variants(path: str) -> list[list[str]]:
    """A schema path as parts; an array of tables also without its index ([[monitor]], wave.component.scale)."""
    parts = path.split(".")
    return [parts] + ([[part for part in parts if part != "0"]] if "0" in parts else [])


# Schema keys and tables; FreeTable keys (mesh.parameters) take anything below them.
_SCHEMA = [variant for path in list(SPECS) + sorted(TABLES) for variant in _variants(path)]
_FREE = [path.split(".") for path, spec in SPECS.items() if isinstance(spec, FreeTable)]


def _part_matches(part: str, schema_part: str) -> bool:
    if schema_part == "NAME":  # any name of a named table
        return re.fullmatch(r"[\w-]+", part) is not None
    if schema_part == "0":  # any index of an array of tables, or the placeholder N
        return re.fullmatch(r"\d+|N", part) is not None
    return part == schema_part


def _matches(parts: list[str], schema: list[str]) -> bool:
    return len(parts) == len(schema) and all(map(_part_matches, parts, schema))


def _python_name(parts: list[str]) -> bool:
    """`static.stage_loads`: a function of pyfem/static.py named without its package, not a key."""
    source = _module_file(parts[:1])
    return source is not None and parts[1] in _top_level_names(source)


def is_scene_key(candidate: str, table_form: bool = False) -> bool:
    parts = candidate.split(".")
    if any(_matches(parts, schema) for schema in _SCHEMA):
        return True
    if any(len(parts) > len(free) and _matches(parts[:len(free)], free) for free in _FREE):
        return True
    if table_form and any(len(schema) > len(parts) and schema[-len(parts)] not in ("NAME", "0")
                          and _matches(parts, schema[-len(parts):]) for schema in _SCHEMA):
        return True  # [damage] for [materials.NAME.damage]: a table named by its last parts
    return len(parts) > 1 and _python_name(parts)


def named_keys(text: str) -> set[tuple[str, bool]]:
    """The scene keys a text names in backticks: (dotted path, written as a [table])."""
    keys = set()
    for span in _CODE.findall(text):
        span = span.strip()
        table = _TABLE_FORM.match(span)
        if table:
            keys.add((table.group(1) + ("." + table.group(2) if table.group(2) else ""), True))
            continue
        dotted = _DOTTED.match(span)
        if dotted and dotted.group(1).split(".")[0] in ROOTS and not dotted.group(1).endswith(
                tuple("." + suffix for suffix in FILE_SUFFIXES)):
            keys.add((dotted.group(1), False))
    return keys


def unknown_keys(document: pathlib.Path) -> list[str]:
    return sorted(key for key, table_form in named_keys(document.read_text())
                  if not is_scene_key(key, table_form))


# --- the tests -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("document", DOCUMENTS, ids=_ids(DOCUMENTS))
def test_named_paths_exist(document):
    assert not named_paths(document)


@pytest.mark.parametrize("document", DOCUMENTS, ids=_ids(DOCUMENTS))
def test_named_modules_exist(document):
    assert not unknown_modules(document)


@pytest.mark.parametrize("document", DOCUMENTS, ids=_ids(DOCUMENTS))
def test_named_scene_keys_exist(document):
    known = KNOWN_UNKNOWN_KEYS.get(document.relative_to(REPOSITORY).as_posix(), set())
    assert set(unknown_keys(document)) == known


def test_the_checks_catch_what_they_are_for(tmp_path):
    """A renamed module, a renamed function, a missing file and a misspelt key are caught; prose is not."""
    document = tmp_path / "doc.md"
    document.write_text(
        "See pyfem/operators.py, `pyfem.operators.build_model`, `pyfem.seismic.freefield`, "
        "[method](../docs/method.md), `wave.surface`, `[static] relaxation`, `[[wave.component]]`, "
        "`materials.sandstone.plasticity.cohesion`, `monitor.0.point`, `--set time.duration=2.0` "
        "`time.duration=2.0`, `boundary.face.ymin`, `mesh.parameters.anything`, `static.json`, "
        "`[damage]`, `[plasticity] cohesion`, `monitor.N.point`, `static.stage_loads`, "
        "workflows/scenes/case1_vertical_{coarse,paper}.toml, "
        "the wave, the static stage, pyfem.\n")
    assert named_paths(document) == ["../docs/method.md"]  # relative to tmp_path: does not exist
    assert unknown_modules(document) == []
    assert unknown_keys(document) == []
    document.write_text(
        "pyfem/operator.py `pyfem.operator` `pyfem.operators.build_models` `wave.surfaces` "
        "`[static] relax` `materials.rock.plasticty` `[wavey]` `static.stage_load`\n")
    assert named_paths(document) == ["pyfem/operator.py"]
    assert unknown_modules(document) == ["pyfem.operator", "pyfem.operators.build_models"]
    assert unknown_keys(document) == ["materials.rock.plasticty", "static.relax", "static.stage_load",
                                      "wave.surfaces", "wavey"]
