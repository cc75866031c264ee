"""The package's import graph, counting function-local imports: no module may take part in an
import cycle (a function-local import that closes a loop is a cycle too; the parts two paths share
go into a module below both, as pyfem/effects.py and pyfem/distributed_parts.py hold them)."""
import ast
import pathlib
import sys

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "pyfem"

def import_graph() -> dict[str, set[str]]:
    """{module: modules of the package it imports anywhere in its body}. `from pkg import sub`
    counts as an import of pkg.sub (the package's __init__ runs first either way; that is not a
    cycle of the code's design)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        modules[name] = path
    graph = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                subs = [f"{source}.{alias.name}" for alias in node.names if f"{source}.{alias.name}" in modules]
                targets = subs if len(subs) == len(node.names) else [source] + subs
            else:
                continue
            graph[name].update(t for t in targets if t in modules and t != name)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_graph_is_read():
    graph = import_graph()
    assert len(graph) > 40 and "pyfem.scene" in graph["pyfem.solver"]  # a guard: the walk found the edges


def test_no_import_cycle():
    found = cycles(import_graph())
    assert not found, f"import cycles: {[sorted(component) for component in found]}"


def test_the_paths_import_one_way():
    """The shared parts sit below the paths that use them: the static stage and the distributed
    modules do not import the serial run, the distributed model's stage and local stepping do not
    import the distributed model (a guard that the edges the cycle was made of stay gone)."""
    graph = import_graph()
    for lower in ("pyfem.static", "pyfem.static_output", "pyfem.distributed_model", "pyfem.distributed_stage",
                  "pyfem.distributed_lts"):
        assert "pyfem.solver" not in graph[lower], lower
    for lower in ("pyfem.distributed_stage", "pyfem.distributed_lts", "pyfem.distributed_parts"):
        assert "pyfem.distributed_model" not in graph[lower], lower
    assert "pyfem.effects" in graph["pyfem.static"] and "pyfem.distributed_parts" in graph["pyfem.distributed_stage"]


def _code_strings(path: pathlib.Path) -> set[str]:
    """The string constants of a module's code (its docstrings left out)."""
    tree = ast.parse(path.read_text())
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return {node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings}


def test_the_program_reads_no_study_results():
    """No module of the package builds a path into workflows/results (the studies' folder): the
    tables the program needs are its own (pyfem/data/)."""
    readers = []
    for path in PACKAGE.rglob("*.py"):
        strings = _code_strings(path)
        if any("workflows/results" in s for s in strings) or {"workflows", "results"} <= strings:
            readers.append(path.name)
    assert not readers, readers


def test_the_study_path_check_sees_a_path(tmp_path):
    """A control: a module joining the two parts is caught."""
    module = tmp_path / "reader.py"
    module.write_text('"""A docstring naming workflows/results is fine."""\nfrom pathlib import Path\n'
                      'TABLE = Path(__file__).parents[1] / "workflows" / "results" / "x.csv"\n')
    assert {"workflows", "results"} <= _code_strings(module)
    module.write_text('"""A docstring naming workflows/results is fine."""\n')
    assert not _code_strings(module)


def test_the_cycle_detector_finds_a_cycle():
    """A control: the detector sees a cycle made of function-local imports."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]
