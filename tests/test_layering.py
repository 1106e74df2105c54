"""Data flows one way (README pipeline): the import graph of the library has no cycle, the
derivation never imports validation, and nothing below the face imports the face (the CLI
modules, the API, the ``gearsym`` package itself).

The graph is built from the source (AST), not from what one run happens to import: every
module of ``gearsym.symbolic`` and ``gearsym.validation``, with its imports at the top level,
inside functions and under ``if TYPE_CHECKING``. An import inside a function still makes the
importer depend on the imported module; hiding it there only postpones the cycle to run time.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Folder of each library package (pyproject.toml [tool.setuptools.package-dir]).
FOLDERS = {"gearsym.symbolic": ROOT / "symbolic", "gearsym.validation": ROOT / "validation"}
#: The face: what the command line and the notebook API are made of. ``gearsym`` itself is
#: the face too (its ``__init__`` imports the API); ``gearsym.symbolic``, ``gearsym.validation``
#: and ``gearsym.templates`` are the library below it.
FACE = (
    "gearsym.cli",
    "gearsym.cmd_",
    "gearsym.commands",
    "gearsym.api",
    "gearsym.interrupts",
    "gearsym.options",
    "gearsym.command_cache",
    "gearsym.__main__",
)


def _modules() -> dict[str, tuple[Path, bool]]:
    """Every module of the library: dotted name → (file, is a package ``__init__``)."""
    found = {}
    for package, folder in FOLDERS.items():
        for path in sorted(folder.rglob("*.py")):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            found[".".join([package, *(parts[:-1] if is_package else parts)])] = (path, is_package)
    return found


MODULES = _modules()


def _is_module(name: str) -> bool:
    """A module or package of gearsym (the library's, or one of the face in ``gearsym/``)."""
    if name in MODULES:
        return True
    parts = name.split(".")
    face = ROOT.joinpath(*parts)
    return parts[0] == "gearsym" and len(parts) == 2 and (face.with_suffix(".py").exists())


def _imported_modules(path: Path, package: str) -> set[str]:
    """Every module ``path`` imports anywhere in its body (top level, inside functions, under
    ``if TYPE_CHECKING``), relative imports resolved against ``package``, and
    ``importlib.import_module("...")`` calls with a literal name. ``from A import B`` is the
    module ``A.B`` when B is a submodule of A, else the module (or package) ``A``."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parent, base] if base else parent)
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.add(sub if _is_module(sub) else base)
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.add(node.args[0].value)
    return found


def _graph() -> dict[str, set[str]]:
    """Module → the library modules it imports.

    Importing ``a.b.c`` also runs the ``__init__`` of ``a.b``; a package's ``__init__`` that
    re-exports its own modules (``codegen``, ``observability``, ``estimators``) is a façade
    above them, so a module's edge to its own enclosing packages is left out (Python has
    initialised them before it runs the module anyway). Importing a package from outside it
    is an edge to its ``__init__``, and that ``__init__``'s imports are its edges."""
    graph = {}
    for name, (path, is_package) in MODULES.items():
        package = name if is_package else name.rsplit(".", 1)[0]
        edges = set()
        for imported in _imported_modules(path, package):
            if imported in MODULES and imported != name and not name.startswith(imported + "."):
                edges.add(imported)
        graph[name] = edges
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (``a → b → … → a``) through every strongly connected component of more than
    one module (Tarjan), or through a module that imports itself."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    cycles = []
    for component in components:
        if len(component) == 1 and component[0] not in graph[component[0]]:
            continue
        members = set(component)
        start = component[0]
        # shortest way back to the start inside the component (breadth first)
        previous: dict[str, str] = {}
        frontier = [start]
        while frontier and start not in previous:
            nxt = []
            for v in frontier:
                for w in sorted(graph[v] & members):
                    if w not in previous:
                        previous[w] = v
                        nxt.append(w)
            frontier = nxt
        cycle = [start]
        v = previous[start]
        while v != start:
            cycle.append(v)
            v = previous[v]
        cycles.append([start, *reversed(cycle[1:]), start])
    return cycles


def test_the_graph_sees_every_module() -> None:
    graph = _graph()
    assert "gearsym.symbolic.description" in graph
    assert "gearsym.validation.checks.c_check" in graph
    assert "gearsym.symbolic.codegen.table" in graph["gearsym.symbolic.codegen.c.emitter"]


def test_a_hidden_cycle_is_found() -> None:
    """The cycle finder itself: an import inside a function closes a cycle as well."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}}
    cycles = sorted(" → ".join(c) for c in _cycles(graph))
    assert cycles == ["a → b → c → a", "e → e"]


def test_no_import_cycles() -> None:
    cycles = _cycles(_graph())
    assert not cycles, "import cycles:\n" + "\n".join(" → ".join(c) for c in cycles)


def test_nothing_below_the_face_imports_the_face() -> None:
    bad = []
    for name, (path, is_package) in MODULES.items():
        package = name if is_package else name.rsplit(".", 1)[0]
        for imported in sorted(_imported_modules(path, package)):
            if imported == "gearsym" or imported.startswith(FACE):
                bad.append(f"{path.relative_to(ROOT)}: imports {imported}")
            if imported.split(".")[0] in ("symbolic", "validation"):
                bad.append(f"{path.relative_to(ROOT)}: imports {imported} (not installed so)")
    assert not bad, "\n".join(bad)


def test_the_derivation_never_imports_validation() -> None:
    graph = _graph()
    bad = [
        f"{name} imports {imported}"
        for name, edges in graph.items()
        if name.startswith("gearsym.symbolic")
        for imported in sorted(edges)
        if imported.startswith("gearsym.validation")
    ]
    assert not bad, "\n".join(bad)


def test_the_description_does_not_import_the_ratios() -> None:
    """The data layer stands below the derivation: parsing a description never imports
    ``ratios`` (not even lazily inside a function); the loader that checks the gear table
    (:mod:`gearsym.symbolic.loader`) sits above both."""
    graph = _graph()
    below, todo = set(), ["gearsym.symbolic.description"]
    while todo:
        for imported in graph[todo.pop()] - below:
            below.add(imported)
            todo.append(imported)
    assert "gearsym.symbolic.ratios" not in below
    assert "gearsym.symbolic.loader" not in below  # the loader imports it, not the reverse


def test_parsing_a_description_loads_no_sympy() -> None:
    """The data layer is data: reading and checking the built-in description (names included)
    imports neither SymPy nor any module of the derivation."""
    code = (
        "import sys\n"
        "from gearsym.symbolic.description import default_config_text\n"
        "from gearsym.symbolic.description_parser import parse_description\n"
        "d = parse_description(default_config_text(), 'built-in')\n"
        "assert d.gears, d\n"
        "print(sorted(m for m in ('sympy', 'numpy', 'gearsym.symbolic.drivetrain') "
        "if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
