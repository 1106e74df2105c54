"""Remembered output of the inspection commands (``gearsym ratios``, ``gearsym model``).

Their output is a pure function of the description file, the options and the code that derives
it, and most of their time is SymPy work (deriving the full model is ~0.2 s) plus SymPy's own
import. A repeated call with the same inputs prints the stored output instead, without
importing SymPy.

The key is the SHA-256 of: the command and its parsed options, the description's path as given
and its bytes (the built-in one when none is given), the bytes of every source file of the
installed ``gearsym`` packages (``gearsym/``, ``symbolic/``) and the versions of SymPy and
mpmath. Any change to one of them is a miss; nothing expires otherwise. An output is stored under
the key of the description bytes the run itself read (recorded by
:func:`~gearsym.symbolic.io.input_files.recorded_reads`), not of those read for the lookup, so a
file saved during the run cannot pair its old key with its new output; any other file the run
read is listed in the entry with its digest and checked again at every hit.

Entries live in ``$GEARSYM_CACHE_DIR``, else ``$XDG_CACHE_HOME/gearsym``, else
``~/.cache/gearsym``; one folder per key, written by the one output writer
(:class:`~gearsym.symbolic.io.output_dir.OutputDir`, with its ``MANIFEST``), read only when its
``MANIFEST`` still matches. ``GEARSYM_NO_CACHE=1`` or ``--no-cache`` turns it off. Only
successful runs are stored (exit 0, and 1 for ``ratios``' "derived ratio differs"); errors
always come from a fresh run. A cache that cannot be written is skipped without a word: it
never changes what a command prints or returns.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = [
    "cache_root",
    "code_fingerprint",
    "description_digest",
    "entry_key",
    "lookup",
    "store",
]

#: Bump when the entry format changes.
FORMAT = 2  # 2: the entry lists the other files the run read
_ENTRY = "output.json"
_SOURCE_SUFFIXES = (".py", ".toml", ".j2")


def cache_root(environ: Mapping[str, str] | None = None) -> Path | None:
    """The cache folder, or ``None`` when caching is off (``GEARSYM_NO_CACHE`` set)."""
    env = os.environ if environ is None else environ
    if env.get("GEARSYM_NO_CACHE", "") not in ("", "0"):
        return None
    if env.get("GEARSYM_CACHE_DIR"):
        return Path(env["GEARSYM_CACHE_DIR"])
    base = env.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "gearsym"


@cache
def code_fingerprint() -> str:
    """SHA-256 over the source files of the installed packages and the SymPy/mpmath versions."""
    import gearsym
    import gearsym.symbolic

    digest = hashlib.sha256(f"format {FORMAT}\n".encode())
    for package in (gearsym, gearsym.symbolic):
        root = Path(package.__file__).parent
        files = sorted(p for p in root.rglob("*") if p.suffix in _SOURCE_SUFFIXES and p.is_file())
        for path in files:
            digest.update(f"{package.__name__}/{path.relative_to(root).as_posix()}\n".encode())
            digest.update(hashlib.sha256(path.read_bytes()).digest())
    for dist in ("sympy", "mpmath"):
        try:
            version = metadata.version(dist)
        except metadata.PackageNotFoundError:
            version = "absent"
        digest.update(f"{dist} {version}\n".encode())
    return digest.hexdigest()


def description_digest(config: str | None) -> str | None:
    """SHA-256 (hex) of the description's bytes now (the built-in one for ``None``), or
    ``None`` when it cannot be read (the fresh run then reports why)."""
    try:
        if config is None:
            from gearsym.symbolic.description import default_config_path

            text = default_config_path().read_bytes()
        else:
            path = Path(config)
            if not path.is_file() or path.stat().st_size > 1 << 20:
                return None
            text = path.read_bytes()
    except (OSError, ImportError):
        return None
    return hashlib.sha256(text).hexdigest()


def entry_key(
    command: str, options: Mapping[str, Any], config: str | None, digest: str | None = None
) -> str | None:
    """The key of one call, or ``None`` when the description cannot be read. ``digest`` is the
    SHA-256 of the description bytes the output was computed from (default: its bytes now)."""
    if digest is None:
        digest = description_digest(config)
        if digest is None:
            return None
    key = hashlib.sha256()
    key.update(code_fingerprint().encode())
    key.update(json.dumps([command, dict(options), config], sort_keys=True).encode())
    key.update(bytes.fromhex(digest))
    return f"{command}-{key.hexdigest()[:40]}"


def _unchanged(reads: Mapping[str, str]) -> bool:
    """Every other file the stored run read still holds the bytes it read then."""
    for path, digest in reads.items():
        try:
            if hashlib.sha256(Path(path).read_bytes()).hexdigest() != digest:
                return False
        except OSError:
            return False
    return True


def lookup(root: Path, key: str) -> tuple[str, str, int] | None:
    """The stored (stdout, stderr, exit status) of ``key``, or ``None`` (missing, or not
    intact)."""
    from gearsym.symbolic.io.output_dir import foreign_content

    folder = root / key
    try:
        if not (folder / _ENTRY).is_file() or foreign_content(folder) is not None:
            return None
        data = json.loads((folder / _ENTRY).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        return None
    stdout, stderr, status = data.get("stdout"), data.get("stderr"), data.get("status")
    if not (isinstance(stdout, str) and isinstance(stderr, str) and isinstance(status, int)):
        return None
    reads = data.get("reads")
    if not isinstance(reads, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in reads.items()
    ):
        return None
    if not _unchanged(reads):
        return None  # a file it read besides the description changed since
    return stdout, stderr, status


def store(
    root: Path,
    key: str,
    command: str,
    stdout: str,
    stderr: str,
    status: int,
    reads: Mapping[str, str] | None = None,
) -> bool:
    """Store one entry through the output writer; ``False`` (and nothing written) when it
    cannot be (read-only cache, another process writing it, a foreign folder). ``reads``: the
    other files the run read (path -> SHA-256), checked again at every hit."""
    from gearsym.symbolic.errors import GearsymError
    from gearsym.symbolic.io.output_dir import OutputDir

    entry = {
        "format": FORMAT,
        "command": command,
        "status": status,
        "stdout": stdout,
        "stderr": stderr,
        "reads": dict(sorted((reads or {}).items())),
    }
    try:
        with OutputDir(root / key, command, shown=str(root / key)) as out:
            (out.path / _ENTRY).write_text(json.dumps(entry) + "\n", encoding="utf-8")
            out.commit()
    except (GearsymError, OSError):
        return False
    return True
