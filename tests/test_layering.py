"""Data flows one way (README pipeline): the derivation never imports validation, and nothing
below the face imports the face (the CLI modules, the API)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FACE = ("gearsym.cli", "gearsym.cmd_", "gearsym.api", "gearsym.interrupts", "gearsym.options")


def _imports(path: Path) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.append(node.module)
    return names


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
