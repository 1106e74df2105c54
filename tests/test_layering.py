"""Data flows one way (README pipeline): the derivation never imports validation, and nothing
below the face imports the face (the CLI modules, the API)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FACE = (
    "gearsym.cli",
    "gearsym.cmd_",
    "gearsym.commands",
    "gearsym.api",
    "gearsym.interrupts",
    "gearsym.options",
)


def _imports(path: Path) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.append(node.module)
    return names


def _imported_modules(path: Path, package: str) -> set[str]:
    """Every module ``path`` imports anywhere in its body (top level, inside functions, under
    ``if TYPE_CHECKING``), with ``from A import B`` also counted as ``A.B`` (B may be a module),
    relative imports resolved against ``package``, and ``importlib.import_module("...")``
    calls with a literal name."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parent, base] if base else parent)
            found.add(base)
            found |= {f"{base}.{a.name}" for a in node.names}
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.add(node.args[0].value)
    return found


def test_the_description_does_not_import_the_ratios() -> None:
    """The data layer stands below the derivation: parsing a description never imports
    ``ratios`` (not even lazily inside a function); the loader that checks the gear table
    (:mod:`gearsym.symbolic.loader`) sits above both."""
    imported = _imported_modules(ROOT / "symbolic" / "description.py", "gearsym.symbolic")
    ratios = sorted(m for m in imported if m == "gearsym.symbolic.ratios" or m.endswith(".ratios"))
    assert not ratios, f"symbolic/description.py imports {ratios}"
    assert "gearsym.symbolic.loader" not in imported  # the loader imports it, not the reverse


def test_the_derivation_never_imports_validation_or_the_face() -> None:
    for path in sorted((ROOT / "symbolic").rglob("*.py")):
        for name in _imports(path):
            assert not name.startswith("gearsym.validation"), f"{path}: imports {name}"
            assert not name.startswith(FACE), f"{path}: imports {name}"
            assert name.split(".")[0] not in ("symbolic", "validation"), f"{path}: {name}"


def test_validation_never_imports_the_face() -> None:
    for path in sorted((ROOT / "validation").rglob("*.py")):
        for name in _imports(path):
            assert not name.startswith(FACE), f"{path}: imports {name}"
            assert name.split(".")[0] not in ("symbolic", "validation"), f"{path}: {name}"
