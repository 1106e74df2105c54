"""The one output writer (issue 9): nothing a user owns is replaced, nothing is half-written.

Every rule of :mod:`gearsym.symbolic.io.output_dir` is exercised on the writer directly, and the
commands that write (simulate, run, sensitivity, fim, generate) are checked to refuse a foreign
``--out`` before any work and to leave nothing behind when interrupted.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any
from unittest import mock

import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.output_dir import MANIFEST, OutputDir, foreign_content

from gearsym import cli

ROOT = Path(__file__).resolve().parents[1]


def _write(target: Path, files: dict[str, str], command: str = "simulate") -> list[Path]:
    with OutputDir(target, command) as out:
        for name, text in files.items():
            (out.path / name).parent.mkdir(parents=True, exist_ok=True)
            (out.path / name).write_text(text)
        return out.commit()


def _tree(root: Path) -> dict[str, bytes]:
    """Every file below ``root`` (hidden ones included) with its content."""
    return {
        p.relative_to(root).as_posix(): (b"<link>" if p.is_symlink() else p.read_bytes())
        for p in sorted(root.rglob("*"))
        if p.is_file() or p.is_symlink()
    }


def _error(call: Any) -> str:
    with pytest.raises(GearsymError) as info:
        call()
    return str(info.value)


# ----------------------------------------------------------------------------- the writer


def test_writes_and_lists_every_file_with_its_sha256(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "out"  # parents created
    paths = _write(target, {"x.csv": "1,2\n", "sub/y.txt": "why\n"})
    assert [p.relative_to(target).as_posix() for p in paths] == ["sub/y.txt", "x.csv", MANIFEST]
    lines = (target / MANIFEST).read_text().splitlines()
    assert lines[0] == (
        "# gearsym simulate output: do not edit, regenerate with `gearsym simulate`."
    )
    listed = dict(reversed(line.split("  ", 1)) for line in lines[2:])
    assert listed == {
        "sub/y.txt": hashlib.sha256(b"why\n").hexdigest(),
        "x.csv": hashlib.sha256(b"1,2\n").hexdigest(),
    }
    assert sorted(p.name for p in target.parent.iterdir()) == ["out"]  # no lock, no staging
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o777 & ~umask


def test_replaces_its_own_output_completely(tmp_path: Path) -> None:
    target = tmp_path / "out"
    _write(target, {"old.txt": "old"})
    _write(target, {"new.txt": "new"}, command="run")  # any gearsym command's output
    assert sorted(_tree(target)) == [MANIFEST, "new.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_an_empty_directory_is_replaced(tmp_path: Path) -> None:
    (tmp_path / "out").mkdir()
    _write(tmp_path / "out", {"a": "1"})
    assert (tmp_path / "out" / "a").read_text() == "1"


@pytest.mark.parametrize(
    ("prepare", "reason"),
    [
        (lambda t: (t.mkdir(), (t / "mine.txt").write_text("keep")), "no gearsym MANIFEST"),
        (lambda t: t.write_text("a file"), "is not a directory"),
        (lambda t: (t.parent / "real").mkdir() or t.symlink_to(t.parent / "real"), "symlink"),
    ],
    ids=["foreign-directory", "plain-file", "symlink"],
)
def test_refuses_what_gearsym_did_not_write(tmp_path: Path, prepare: Any, reason: str) -> None:
    target = tmp_path / "out"
    prepare(target)
    before = _tree(tmp_path)
    message = _error(lambda: OutputDir(target, "simulate").open())
    assert reason in message and message.startswith(f"{target}: --out: ")
    assert _tree(tmp_path) == before


def test_refuses_a_gearsym_directory_with_a_users_file_or_a_changed_file(tmp_path: Path) -> None:
    target = tmp_path / "out"
    _write(target, {"x.csv": "1\n"})
    (target / "notes.txt").write_text("my notes")
    assert "holds notes.txt, which gearsym did not write" in _error(
        lambda: OutputDir(target, "simulate").open()
    )
    (target / "notes.txt").unlink()
    (target / "x.csv").write_text("edited\n")
    assert "x.csv was changed after gearsym wrote it" in _error(
        lambda: OutputDir(target, "simulate").open()
    )
    (target / "x.csv").write_text("1\n")
    os.symlink("/etc/passwd", target / "link")
    assert "holds link" in _error(lambda: OutputDir(target, "simulate").open())
    assert (target / "x.csv").read_text() == "1\n"


def test_refuses_the_current_directory_its_ancestors_and_root(
    tmp_path: Path, monkeypatch: Any
) -> None:
    work = tmp_path / "here"
    work.mkdir()
    monkeypatch.chdir(work)
    for out in (".", "..", str(work), "../here/.", "/"):
        message = _error(lambda out=out: OutputDir(out, "simulate"))
        assert "current directory" in message or "root" in message, message
    assert _error(lambda: OutputDir("", "simulate")).endswith("must name a directory")


def test_a_parent_that_is_a_file_is_one_error_and_nothing_is_created(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    message = _error(lambda: OutputDir(tmp_path / "file" / "sub" / "out", "fim").open())
    assert "cannot create" in message
    assert _tree(tmp_path) == {"file": b"x"}


def _as_unprivileged_user() -> list[str]:
    """A command prefix that drops root (a read-only directory does not stop root)."""
    if os.geteuid() != 0:
        return []
    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: cannot make a directory read-only")
    prefix = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
    probe = subprocess.run(
        [*prefix, sys.executable, "-c", "import gearsym.cli"], cwd=ROOT, capture_output=True
    )
    if probe.returncode != 0:
        pytest.skip("the checkout is not readable by an unprivileged user")
    return prefix


def test_a_read_only_parent_is_refused_before_the_work() -> None:
    prefix = _as_unprivileged_user()
    base = Path(tempfile.mkdtemp(prefix="gearsym-ro-"))  # pytest's tmp_path is root-only
    try:
        base.chmod(0o755)
        parent = base / "ro"
        parent.mkdir()
        parent.chmod(0o555)
        result = subprocess.run(
            [*prefix, sys.executable, "-m", "gearsym", "simulate", "--out", str(parent / "out")],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        assert result.returncode == 2
        assert result.stderr.strip().splitlines() == [
            f"gearsym: {parent / 'out'}: --out: cannot write in {parent} (permission denied)"
        ]  # one line, and no progress line: nothing was simulated
        assert list(parent.iterdir()) == []
    finally:
        shutil.rmtree(base)


def test_an_error_inside_leaves_the_old_output_and_no_trace(tmp_path: Path) -> None:
    target = tmp_path / "out"
    _write(target, {"old.txt": "old"})
    before = _tree(tmp_path)
    with pytest.raises(RuntimeError), OutputDir(target, "simulate") as out:
        (out.path / "half.csv").write_text("1,")
        raise RuntimeError("disk full")
    assert _tree(tmp_path) == before
    fresh = tmp_path / "new" / "deep" / "out"
    with pytest.raises(RuntimeError), OutputDir(fresh, "simulate"):
        raise RuntimeError("interrupted")
    assert not (tmp_path / "new").exists()  # the parents it created are gone too


def test_checks_again_at_the_moment_of_replacement(tmp_path: Path) -> None:
    """A target replaced by someone else while the command ran is given back untouched."""
    target = tmp_path / "out"
    _write(target, {"old.txt": "old"})
    with OutputDir(target, "simulate") as out:
        (out.path / "new.txt").write_text("new")
        # meanwhile a user puts their own folder there
        os.rename(target, tmp_path / "gearsyms")
        target.mkdir()
        (target / "thesis.tex").write_text("precious")
        message = _error(out.commit)
    assert "no gearsym MANIFEST" in message and "changed while gearsym ran" in message
    assert _tree(target) == {"thesis.tex": b"precious"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gearsyms", "out"]


def test_a_second_writer_on_the_same_target_is_refused(tmp_path: Path) -> None:
    target = tmp_path / "out"
    with OutputDir(target, "simulate") as first:
        assert "another gearsym process is writing it" in _error(
            lambda: OutputDir(target, "generate").open()
        )
        (first.path / "a").write_text("1")
        first.commit()
    _write(target, {"b": "2"})  # released
    assert sorted(_tree(target)) == [MANIFEST, "b"]


_KILLED_WRITER = """
import os, sys, time
from gearsym.symbolic.io.output_dir import OutputDir
out = OutputDir(sys.argv[1], "simulate").open()
(out.path / "half.csv").write_text("1,")
if sys.argv[2] == "between-renames":
    target = out.target
    os.rename(target, target.parent / f".{target.name}.gearsym-old-{os.getpid()}-abcdefgh")
print("ready", flush=True)
time.sleep(60)
"""


@pytest.mark.parametrize("moment", ["while-writing", "between-renames"])
def test_the_next_run_cleans_up_after_a_killed_one(tmp_path: Path, moment: str) -> None:
    """SIGKILL cannot be caught: the next writer removes the dead run's staging directory
    and puts back an old output that was moved aside but not yet replaced."""
    target = tmp_path / "out"
    _write(target, {"old.txt": "old"})
    proc = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(target), moment],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    proc.kill()
    proc.wait()
    leftovers = sorted(p.name for p in tmp_path.iterdir() if p.name != "out")
    assert any("gearsym-staging" in name for name in leftovers), leftovers
    assert (target / "old.txt").exists() == (moment == "while-writing")
    with OutputDir(target, "simulate") as out:  # the next run
        assert (target / "old.txt").read_text() == "old"  # put back before anything else
        (out.path / "new.txt").write_text("new")
        out.commit()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert sorted(_tree(target)) == [MANIFEST, "new.txt"]


def test_foreign_content_reads_no_more_than_it_must(tmp_path: Path) -> None:
    assert foreign_content(tmp_path / "missing") is None
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / MANIFEST).write_text("# not gearsym\n")
    assert foreign_content(tmp_path / "m") == (
        "exists and was not written by gearsym (no gearsym MANIFEST)"
    )


# ----------------------------------------------------------------------------- the commands


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--out", "{out}"],
        ["run", "--out", "{out}"],
        ["sensitivity", "--out", "{out}"],
        ["fim", "--out", "{out}"],
        ["generate", "--out", "{out}"],
    ],
    ids=lambda argv: argv[0],
)
def test_every_writing_command_refuses_a_foreign_out_before_the_work(
    tmp_path: Path, capsys: Any, argv: list[str]
) -> None:
    target = tmp_path / "mine"
    target.mkdir()
    (target / "thesis.tex").write_text("precious")
    from gearsym.validation.sim import simulate

    def no_work(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("the long work started before --out was checked")

    with (
        mock.patch.object(simulate, "simulate", no_work),
        mock.patch("gearsym.symbolic.export.generate.generate_tree", no_work),
    ):
        status = cli.main([a.format(out=target) for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert err == [
        f"gearsym: {target}: --out: exists and was not written by gearsym (no "
        "gearsym MANIFEST); not replacing it"
    ]
    assert _tree(tmp_path) == {"mine/thesis.tex": b"precious"}


def test_sigterm_during_a_run_leaves_nothing(tmp_path: Path) -> None:
    """SIGTERM while `gearsym run` works (its simulation has started; the sensitivities and
    FIM take many more seconds): exit 143, one line, no staging folder, no lock, no output."""
    target = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "gearsym", "run", "--out", str(target)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    seen = []
    for line in proc.stderr:  # wait until the staging directory exists and the work runs
        seen.append(line)
        if "integrating" in line:
            break
    assert "integrating" in seen[-1], "".join(seen)
    proc.send_signal(signal.SIGTERM)
    rest = proc.stderr.read()
    assert proc.wait(timeout=60) == 143
    assert rest.strip().splitlines()[-1] == "gearsym: terminated; nothing was written"
    assert "Traceback" not in rest
    assert list(tmp_path.iterdir()) == []


def test_sigterm_turned_into_a_library_error_still_exits_143(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """CasADi's integrator may swallow the Terminated its signal check raised and fail; the
    library then reports an error of the run (a GearsymError). The signal came first: exit 143,
    not the bad-input exit 2 (the CI of stop 41 saw 2 here)."""
    import argparse

    from gearsym.interrupts import Terminated

    def swallowing_native_call(args: argparse.Namespace) -> int:
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(30)  # the handler runs here, as in a native call that checks signals
        except Terminated:
            raise GearsymError(
                "gearbox.toml", "simulate", "integration failed at t = 0.1 s"
            ) from None
        raise AssertionError("SIGTERM was not delivered")

    parsed = argparse.Namespace(func=swallowing_native_call, cacheable=False)
    with mock.patch.object(cli, "build_parser") as build:
        build.return_value.parse_args.return_value = parsed
        status = cli.main([])
    assert status == 143
    assert capsys.readouterr().err.strip().splitlines() == [
        "gearsym: terminated; nothing was written"
    ]
