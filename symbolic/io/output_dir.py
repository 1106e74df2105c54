"""The one writer of every output directory: nothing a user owns is ever replaced.

Every command that writes files (``generate``, ``simulate``, ``run``, ``sensitivity``,
``fim``) writes them into a staging directory next to its target ``DIR`` and swaps the
staging directory in only when everything is written. The rules:

* ``DIR`` is replaced only if it does not exist, is an empty directory, or was written by
  gearsym: its ``MANIFEST`` starts with a gearsym marker line and lists every file below it
  with its SHA-256. A file added or changed since gearsym wrote it, a symlink, a plain file
  at ``DIR``, the current directory or one of its ancestors: refused, one line, exit 2.
* The check runs when the command starts (before the long work) and again at the moment of
  replacement: the old ``DIR`` is first renamed aside (one atomic rename), checked there, and
  renamed back if it turned out not to be gearsym's.
* A lock file ``.DIR.gearsym-lock`` next to ``DIR`` (``flock``, released by the kernel when a
  process dies) keeps two gearsym processes from writing the same ``DIR``.
* Staging directories of a killed run (``.DIR.gearsym-staging-*``) are removed by the next
  run on the same ``DIR``; an old ``DIR`` left aside by a run killed between its two renames
  (``.DIR.gearsym-old-*``) is put back.

A command that writes one file (``gearsym draw --out FILE.svg``, ``gearsym export-fmu --out
FILE.fmu``, ``gearsym export-a2l --out FILE.a2l``) goes through :class:`OutputFile`, with the
same rules for a single file. A lone file has no ``MANIFEST`` beside it, so it carries its own
proof of origin: a signature that holds the SHA-256 of the rest of the file (an SVG: a closing
XML comment; a PNG: a ``tEXt`` chunk before ``IEND``; an FMU, a zip archive: the archive
comment, which every zip reader skips; an A2L file: a closing ``/* ... */`` comment, which
every ASAP2 reader skips; a recording of ``gearsym export-measurement``, MDF4 or CSV: a
closing ``# gearsym ...`` line, after the last MDF4 block, a comment line to a CSV reader).
``FILE`` is replaced only if it does not exist or its signature matches its content: a user's
file, or a gearsym picture edited since, is refused. The file is written next to ``FILE``
(``.FILE.gearsym-staging-*``) and renamed over it in one atomic step, under the same lock.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from types import TracebackType

from gearsym.symbolic.errors import GearsymError

__all__ = [
    "MANIFEST",
    "PICTURE_SUFFIXES",
    "SIGNED_SUFFIXES",
    "OutputDir",
    "OutputFile",
    "foreign_file",
    "sign_file",
    "signed_by_gearsym",
    "foreign_content",
    "manifest_marker",
    "manifest_text",
]

#: Name of the file that marks a gearsym output directory and lists its files.
MANIFEST = "MANIFEST"
_MARKER = re.compile(
    r"# gearsym ([a-z][a-z0-9-]*) output: do not edit, regenerate with `gearsym \1`\."
)
_ENTRY = re.compile(r"([0-9a-f]{64})  (\S(?:.*\S)?)")
_STAGING = "gearsym-staging-"
_OLD = "gearsym-old-"


def manifest_marker(command: str) -> str:
    """First line of the ``MANIFEST`` a ``gearsym <command>`` writes."""
    line = f"# gearsym {command} output: do not edit, regenerate with `gearsym {command}`."
    if not _MARKER.fullmatch(line):
        raise ValueError(f"not a command name: {command!r}")
    return line


def manifest_text(files: Mapping[str, bytes], command: str) -> str:
    """``MANIFEST``: the marker, then ``<sha256>  <path>`` for every file (sorted by path)."""
    lines = [manifest_marker(command), f"# {len(files)} files, SHA-256 of each:"]
    for path in sorted(files):
        lines.append(f"{hashlib.sha256(files[path]).hexdigest()}  {path}")
    return "\n".join(lines) + "\n"


def _parse_manifest(path: Path) -> dict[str, str] | None:
    """``{relative path: sha256}`` of a gearsym ``MANIFEST``; ``None`` if it is not one."""
    try:
        if path.is_symlink() or not path.is_file() or path.stat().st_size > 16 << 20:
            return None
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    if not lines or not _MARKER.fullmatch(lines[0]):
        return None
    entries = {}
    for line in lines[1:]:
        if line.startswith("#"):
            continue
        match = _ENTRY.fullmatch(line)
        if match is None:
            return None
        entries[match.group(2)] = match.group(1)
    return entries


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _walk_files(root: Path) -> Iterator[tuple[str, Path]]:
    """Every entry below ``root`` that is not a plain directory: (relative path, path)."""
    for folder, dirs, files in os.walk(root, followlinks=False):
        base = Path(folder)
        for name in sorted(dirs):
            if (base / name).is_symlink():
                yield (base / name).relative_to(root).as_posix(), base / name
        for name in sorted(files):
            yield (base / name).relative_to(root).as_posix(), base / name


def foreign_content(target: Path) -> str | None:
    """Why ``target`` must not be replaced, or ``None`` if gearsym may replace it."""
    if target.is_symlink():
        return "is a symlink"
    if not target.exists():
        return None
    if not target.is_dir():
        return "is not a directory"
    try:
        if not any(target.iterdir()):
            return None
    except OSError as err:
        return f"cannot be read ({err.strerror})"
    listed = _parse_manifest(target / MANIFEST)
    if listed is None:
        return "exists and was not written by gearsym (no gearsym MANIFEST)"
    for relative, path in _walk_files(target):
        if relative == MANIFEST:
            continue
        if path.is_symlink() or not path.is_file():
            return f"holds {relative}, which gearsym did not write (not a plain file)"
        if relative not in listed:
            return f"holds {relative}, which gearsym did not write"
        try:
            if _sha256(path) != listed[relative]:
                return f"{relative} was changed after gearsym wrote it"
        except OSError as err:
            return f"{relative} cannot be read ({err.strerror})"
    return None


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: A full disk, an exceeded quota, a file too large, a read-only file system or an I/O error
#: while writing: the machine's condition, reported in one line like bad input.
STORAGE_ERRORS = frozenset(
    getattr(errno, name)
    for name in ("ENOSPC", "EDQUOT", "EFBIG", "EROFS", "EIO")
    if hasattr(errno, name)
)


class OutputDir:
    """Stage the files of one command and swap them into ``target`` when complete.

    Use it as a context manager around the whole command, so that the checks run before the
    long work::

        with OutputDir(args.out, "simulate") as out:
            result = simulate(...)                 # slow
            write_results(result, out.path)        # into the staging directory
            paths = out.commit()                   # atomic swap; the final paths

    Leaving the block without :meth:`commit` (an error, a failed check, Ctrl-C, SIGTERM)
    removes the staging directory and leaves ``target`` as it was.
    """

    def __init__(
        self,
        target: str | Path,
        command: str,
        *,
        shown: str | None = None,
        before_commit: Callable[[], None] | None = None,
    ) -> None:
        """``before_commit`` runs first thing in :meth:`commit`; an exception it raises (e.g.
        a cancellation the caller noticed) leaves ``target`` untouched."""
        self.before_commit = before_commit
        self.shown = shown if shown is not None else str(target)
        self.command = command
        manifest_marker(command)  # validates the name early
        if str(target).strip() == "":  # Path("") would be the current directory
            raise self._error("must name a directory")
        try:
            self.target = self._resolve(Path(target))
        except OSError as err:
            raise self._error(f"cannot be inspected ({err.strerror})") from None
        self._lock_fd: int | None = None
        self._staging: Path | None = None
        self._created_parents: list[Path] = []
        self.committed = False

    # ------------------------------------------------------------------ set-up

    def _error(self, reason: str) -> GearsymError:
        return GearsymError(self.shown, "--out", reason)

    def _resolve(self, target: Path) -> Path:
        if target.is_symlink():
            raise self._error("is a symlink; name the directory itself")
        absolute = Path(os.path.abspath(target))
        if absolute.parent == absolute:
            raise self._error("is the file system root")
        # resolve the parent only: the last component is the directory gearsym owns
        try:
            absolute = absolute.parent.resolve() / absolute.name
        except (OSError, RuntimeError) as err:
            raise self._error(f"cannot be resolved ({err})") from None
        cwd = Path.cwd().resolve()
        if absolute == cwd or absolute in cwd.parents:
            raise self._error("is the current directory or contains it; name a subdirectory")
        home = Path.home().resolve()
        if absolute == home or absolute in home.parents:
            raise self._error("is the home directory or contains it; name a subdirectory")
        return absolute

    @property
    def path(self) -> Path:
        """The staging directory: write every output file below it."""
        if self._staging is None:
            raise RuntimeError("OutputDir is not open")
        return self._staging

    def open(self) -> OutputDir:
        """Check ``target``, take the lock, clean up after killed runs, create the staging
        directory. Raises :class:`GearsymError` (nothing written) when any of that fails."""
        try:
            reason = foreign_content(self.target)
        except OSError as err:
            raise self._error(f"cannot be inspected ({err.strerror})") from None
        if reason is not None:
            raise self._error(f"{reason}; not replacing it")
        parent = self.target.parent
        self._make_parents(parent)
        try:
            self._lock()
            self._recover_killed_runs()
            reason = foreign_content(self.target)  # again, now under the lock
            if reason is not None:
                raise self._error(f"{reason}; not replacing it")
            self._staging = Path(
                tempfile.mkdtemp(prefix=f".{self.target.name}.{_STAGING}{os.getpid()}-", dir=parent)
            )
            os.chmod(self._staging, 0o777 & ~_umask())  # mkdtemp's 0700 would outlive the swap
        except BaseException:
            self.discard()
            raise
        return self

    def _make_parents(self, parent: Path) -> None:
        missing = []
        for folder in (parent, *parent.parents):
            if folder.exists():
                break
            missing.append(folder)
        for folder in reversed(missing):
            try:
                folder.mkdir()
            except FileExistsError:
                continue
            except OSError as err:
                self._remove_created_parents()
                raise self._error(f"cannot create {folder} ({err.strerror})") from None
            self._created_parents.append(folder)
        if not parent.is_dir():
            raise self._error(f"{parent} is not a directory")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise self._error(f"cannot write in {parent} (permission denied)")

    def _lock(self) -> None:
        lock = self.target.parent / f".{self.target.name}.gearsym-lock"
        for _ in range(5):
            try:
                fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            except OSError as err:
                raise self._error(f"cannot create the lock file {lock} ({err.strerror})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as err:
                os.close(fd)
                if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise self._error(
                        f"another gearsym process is writing it (lock {lock.name}); "
                        "wait for it or choose another directory"
                    ) from None
                raise
            try:
                same = os.stat(lock).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:  # not unlinked by a releasing process between our open and flock
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                self._lock_fd = fd
                self._lock_path = lock
                return
            os.close(fd)
        raise self._error(f"cannot take the lock {lock.name}")

    def _unlock(self) -> None:
        if self._lock_fd is None:
            return
        try:
            os.unlink(self._lock_path)
        except OSError:
            pass
        os.close(self._lock_fd)
        self._lock_fd = None

    def _leftovers(self, kind: str) -> list[Path]:
        prefix = f".{self.target.name}.{kind}"
        return sorted(
            p
            for p in self.target.parent.iterdir()
            if p.name.startswith(prefix)
            and re.fullmatch(r"\d+-[^/]+", p.name[len(prefix) :])
            and p.is_dir()
            and not p.is_symlink()
        )

    def _recover_killed_runs(self) -> None:
        """Under the lock no other gearsym writes this target, so every staging or old
        directory of it belongs to a run that was killed."""
        olds = [p for p in self._leftovers(_OLD) if foreign_content(p) is None]
        if olds and not self.target.exists() and not self.target.is_symlink():
            os.rename(olds.pop(), self.target)  # killed between its two renames: put it back
        for leftover in olds + self._leftovers(_STAGING):
            shutil.rmtree(leftover, ignore_errors=True)

    # ------------------------------------------------------------------ commit / discard

    def commit(self) -> list[Path]:
        """Write ``MANIFEST`` and swap the staging directory in; returns the final paths of
        every file written (``MANIFEST`` last)."""
        if self.before_commit is not None:
            self.before_commit()
        staging = self.path
        written = self._seal(staging)
        old: Path | None = None
        if self.target.exists() or self.target.is_symlink():
            old = Path(
                tempfile.mkdtemp(
                    prefix=f".{self.target.name}.{_OLD}{os.getpid()}-", dir=self.target.parent
                )
            )
            os.rmdir(old)  # a free name next to the target, for one atomic rename
            os.rename(self.target, old)
            reason = foreign_content(old)
            if reason is not None:  # replaced by someone else since the start: give it back
                self._put_back(old)
                raise self._error(f"{reason} (it changed while gearsym ran); not replacing it")
        try:
            os.rename(staging, self.target)
        except OSError as err:
            if old is not None:
                self._put_back(old)
            raise self._error(f"cannot move the new output into place ({err.strerror})") from None
        self._staging = None
        self.committed = True
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        self._created_parents.clear()
        self._unlock()
        return [self.target / relative for relative in written]

    def _put_back(self, old: Path) -> None:
        try:
            os.rename(old, self.target)
        except OSError:
            raise self._error(
                f"something appeared at it while gearsym ran; the previous content is in {old}"
            ) from None

    def _seal(self, staging: Path) -> list[str]:
        files: dict[str, Path] = {}
        for relative, path in _walk_files(staging):
            if path.is_symlink() or not path.is_file():
                raise RuntimeError(f"gearsym wrote a non-file {relative}")
            files[relative] = path
        digests = {relative: _sha256(path) for relative, path in files.items()}
        manifest = staging / MANIFEST
        if MANIFEST in files:  # the content brought its own (generate): it must be complete
            listed = _parse_manifest(manifest)
            expected = {k: v for k, v in digests.items() if k != MANIFEST}
            if listed != expected:
                raise RuntimeError("the MANIFEST written with the output does not match it")
        else:
            lines = [manifest_marker(self.command), f"# {len(digests)} files, SHA-256 of each:"]
            lines += [f"{digests[relative]}  {relative}" for relative in sorted(digests)]
            manifest.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return sorted(r for r in digests if r != MANIFEST) + [MANIFEST]

    def discard(self) -> None:
        """Remove the staging directory (and parents this object created); release the lock."""
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None
        self._unlock()
        self._remove_created_parents()

    def _remove_created_parents(self) -> None:
        for folder in reversed(self._created_parents):
            try:
                folder.rmdir()
            except OSError:
                break
        self._created_parents.clear()

    def __enter__(self) -> OutputDir:
        return self.open()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if not self.committed:
            self.discard()
        if isinstance(value, OSError) and value.errno in STORAGE_ERRORS:
            # a full disk (or quota, read-only file system) while staging: one line naming the
            # user's folder, not the staging path, and the staging folder is gone
            raise GearsymError(
                self.shown, "", f"cannot write: {value.strerror}; nothing was written"
            ) from None


# ----------------------------------------------------------------------------- single files

#: Formats :class:`OutputFile` can sign (lower-case suffixes).
SIGNED_SUFFIXES = (".svg", ".png", ".fmu", ".a2l", ".mf4", ".csv")
#: Formats signed by a closing ``# gearsym ...`` line: a CSV reader skips ``#`` lines, an MDF4
#: reader follows the block links from the file's start and never reaches bytes after the
#: last block.
_LINE_SIGNED = (".mf4", ".csv")
#: What :class:`OutputFile` accepts unless told otherwise (``gearsym draw``).
PICTURE_SUFFIXES = (".svg", ".png")
_ZIP_END = b"PK\x05\x06"  # end-of-central-directory record: 22 bytes, then the comment
_ZIP_SIGNATURE = re.compile(
    rb"gearsym ([a-z][a-z0-9-]*) output: do not edit, regenerate with gearsym \1; "
    rb"sha256 ([0-9a-f]{64}) of the archive without this comment"
)
_A2L_SIGNATURE = re.compile(
    rb"/\* gearsym ([a-z][a-z0-9-]*) output: do not edit, regenerate with gearsym \1; "
    rb"sha256 ([0-9a-f]{64}) of everything before this comment \*/\n"
)
_LINE_SIGNATURE = re.compile(
    rb"# gearsym ([a-z][a-z0-9-]*) output: do not edit, regenerate with gearsym \1; "
    rb"sha256 ([0-9a-f]{64}) of everything before this line\n"
)
_PNG_HEADER = b"\x89PNG\r\n\x1a\n"
_PNG_KEYWORD = b"gearsym"
_SVG_SIGNATURE = re.compile(
    rb"<!-- gearsym ([a-z][a-z0-9-]*) output: do not edit, regenerate with gearsym \1; "
    rb"sha256 ([0-9a-f]{64}) of everything before this comment -->\n"
)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    import zlib

    return len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(4, "big")


def _png_chunks(data: bytes) -> list[tuple[int, int, bytes]] | None:
    """``(start, end, type)`` of every chunk of a PNG, or ``None`` if it is not one."""
    if not data.startswith(_PNG_HEADER):
        return None
    chunks, at = [], len(_PNG_HEADER)
    while at + 12 <= len(data):
        length = int.from_bytes(data[at : at + 4], "big")
        end = at + 12 + length
        if end > len(data):
            return None
        chunks.append((at, end, data[at + 4 : at + 8]))
        at = end
    return chunks if at == len(data) and chunks and chunks[-1][2] == b"IEND" else None


def sign_file(data: bytes, suffix: str, command: str) -> bytes:
    """``data`` with gearsym's signature: the SHA-256 of ``data`` in a closing comment (SVG,
    A2L), a ``tEXt`` chunk before ``IEND`` (PNG) or the archive comment (FMU); the content
    itself is unchanged."""
    manifest_marker(command)  # validates the name
    digest = hashlib.sha256(data).hexdigest()
    if suffix.lower() == ".svg":
        comment = (
            f"<!-- gearsym {command} output: do not edit, regenerate with gearsym {command}; "
            f"sha256 {digest} of everything before this comment -->\n"
        )
        return data + comment.encode("ascii")
    if suffix.lower() == ".a2l":
        if not data.endswith(b"\n"):
            raise ValueError("an A2L file to sign ends with a newline")
        comment = (
            f"/* gearsym {command} output: do not edit, regenerate with gearsym {command}; "
            f"sha256 {digest} of everything before this comment */\n"
        )
        return data + comment.encode("ascii")
    if suffix.lower() in _LINE_SIGNED:
        if suffix.lower() == ".csv" and not data.endswith(b"\n"):
            raise ValueError("a CSV file to sign ends with a newline")
        line = (
            f"# gearsym {command} output: do not edit, regenerate with gearsym {command}; "
            f"sha256 {digest} of everything before this line\n"
        )
        return data + line.encode("ascii")
    if suffix.lower() == ".png":
        chunks = _png_chunks(data)
        if chunks is None:
            raise ValueError("not a PNG")
        iend = chunks[-1][0]
        text = _PNG_KEYWORD + b"\0" + f"{command} sha256 {digest}".encode("ascii")
        return data[:iend] + _png_chunk(b"tEXt", text) + data[iend:]
    if suffix.lower() == ".fmu":
        # The archive comment closes a zip, its length the last field before it: an archive
        # written without a comment ends with an end record whose length field is 0.
        at = len(data) - 22
        if at < 0 or data[at : at + 4] != _ZIP_END or data[-2:] != b"\0\0":
            raise ValueError("not a zip archive without a comment")
        comment = (
            f"gearsym {command} output: do not edit, regenerate with gearsym {command}; "
            f"sha256 {digest} of the archive without this comment"
        ).encode("ascii")
        return data[:-2] + len(comment).to_bytes(2, "little") + comment
    raise ValueError(f"cannot sign a {suffix!r} file")


def signed_by_gearsym(data: bytes, suffix: str) -> bool:
    """True if ``data`` carries a gearsym signature that matches its content."""
    if suffix.lower() == ".svg":
        at = data.rfind(b"<!-- gearsym ")
        match = _SVG_SIGNATURE.fullmatch(data[at:]) if at >= 0 else None
        return match is not None and hashlib.sha256(data[:at]).hexdigest().encode() == match[2]
    if suffix.lower() == ".a2l":
        at = data.rfind(b"/* gearsym ")
        match = _A2L_SIGNATURE.fullmatch(data[at:]) if at >= 0 else None
        return match is not None and hashlib.sha256(data[:at]).hexdigest().encode() == match[2]
    if suffix.lower() in _LINE_SIGNED:
        at = data.rfind(b"# gearsym ")
        match = _LINE_SIGNATURE.fullmatch(data[at:]) if at >= 0 else None
        return match is not None and hashlib.sha256(data[:at]).hexdigest().encode() == match[2]
    if suffix.lower() == ".png":
        chunks = _png_chunks(data)
        if chunks is None or len(chunks) < 2 or chunks[-2][2] != b"tEXt":
            return False
        start, end, _ = chunks[-2]
        keyword, _, text = data[start + 8 : end - 4].partition(b"\0")
        match = re.fullmatch(rb"[a-z][a-z0-9-]* sha256 ([0-9a-f]{64})", text)
        if keyword != _PNG_KEYWORD or match is None:
            return False
        return hashlib.sha256(data[:start] + data[end:]).hexdigest().encode() == match[1]
    if suffix.lower() == ".fmu":
        at = data.rfind(_ZIP_END)
        if at < 0 or at + 22 > len(data):
            return False
        length = int.from_bytes(data[at + 20 : at + 22], "little")
        match = _ZIP_SIGNATURE.fullmatch(data[at + 22 :])
        if at + 22 + length != len(data) or match is None:
            return False
        unsigned = data[: at + 20] + b"\0\0"
        return hashlib.sha256(unsigned).hexdigest().encode() == match[2]
    return False


def foreign_file(target: Path) -> str | None:
    """Why the file ``target`` must not be replaced, or ``None`` if gearsym may replace it."""
    if target.is_symlink():
        return "is a symlink"
    if not target.exists():
        return None
    if not target.is_file():
        return "exists and is not a plain file"
    try:
        if target.stat().st_size > 256 << 20:
            return "exists and was not written by gearsym (too large to be a gearsym file)"
        data = target.read_bytes()
    except OSError as err:
        return f"cannot be read ({err.strerror})"
    if not signed_by_gearsym(data, target.suffix):
        return "exists and was not written by gearsym (no gearsym signature, or changed since)"
    return None


class OutputFile(OutputDir):
    """Write one signed file ``target`` atomically, with the rules of :class:`OutputDir`::

        with OutputFile(args.out, "draw") as out:
            data = render(...)
            path = out.commit(data)   # signed, renamed over target

    The suffix must be one of ``suffixes`` (a subset of :data:`SIGNED_SUFFIXES`; default the
    pictures). Leaving the block without :meth:`commit` leaves ``target`` as it was.
    """

    def __init__(
        self,
        target: str | Path,
        command: str,
        *,
        shown: str | None = None,
        suffixes: tuple[str, ...] = PICTURE_SUFFIXES,
    ) -> None:
        unknown = [s for s in suffixes if s not in SIGNED_SUFFIXES]
        if unknown or not suffixes:
            raise ValueError(f"cannot sign {unknown or 'nothing'}; signable: {SIGNED_SUFFIXES}")
        expected = " or ".join(suffixes)
        if str(target).strip() == "":
            raise GearsymError("command line", "--out", f"is empty; name a {expected} file")
        super().__init__(target, command, shown=shown)
        if self.target.suffix.lower() not in suffixes:
            raise self._error(
                f"unsupported file type {self.target.suffix or '(none)'!r}; expected {expected}"
            )

    def _check(self) -> None:
        try:
            reason = foreign_file(self.target)
        except OSError as err:
            raise self._error(f"cannot be inspected ({err.strerror})") from None
        if reason is not None:
            raise self._error(f"{reason}; not replacing it")

    def open(self) -> OutputFile:
        """Check ``target``, create its folder, take the lock, remove files of killed runs."""
        self._check()
        self._make_parents(self.target.parent)
        try:
            self._lock()
            prefix = f".{self.target.name}.{_STAGING}"
            for leftover in self.target.parent.iterdir():
                if leftover.name.startswith(prefix) and leftover.is_file():
                    leftover.unlink(missing_ok=True)  # under the lock: a killed run's
            self._check()
        except BaseException:
            self.discard()
            raise
        self._opened = True
        return self

    @property
    def path(self) -> Path:
        raise RuntimeError("OutputFile has no staging directory; pass the bytes to commit()")

    def commit(self, data: bytes) -> Path:  # type: ignore[override]
        """Sign ``data``, write it next to ``target`` and rename it over ``target``."""
        if not getattr(self, "_opened", False):
            raise RuntimeError("OutputFile is not open")
        signed = sign_file(data, self.target.suffix, self.command)
        fd, temporary = tempfile.mkstemp(
            prefix=f".{self.target.name}.{_STAGING}{os.getpid()}-", dir=self.target.parent
        )
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(signed)
            os.chmod(temporary, 0o666 & ~_umask())  # mkstemp's 0600 would outlive the rename
            self._check()  # again, at the moment of replacement
            os.replace(temporary, self.target)
        except OSError as err:
            Path(temporary).unlink(missing_ok=True)
            raise self._error(f"cannot be written ({err.strerror})") from None
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
        self.committed = True
        self._created_parents.clear()
        self._unlock()
        return self.target

    def discard(self) -> None:
        """Release the lock; remove the folders this object created (nothing was written)."""
        self._opened = False
        self._unlock()
        self._remove_created_parents()

    def __enter__(self) -> OutputFile:
        return self.open()
