"""The output cache of `gearsym ratios` and `gearsym model` (gearsym/command_cache.py).

Expected outputs come from a fresh run with the cache off (the independent path); the tests
check that a remembered output is byte-identical to it, that every input of the key
invalidates it, and that a damaged entry is never trusted.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from gearsym.symbolic.description import default_config_text

from gearsym.command_cache import cache_root, entry_key


def gearsym(cache: Path | None, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("GEARSYM_")}
    if cache is None:
        env["GEARSYM_NO_CACHE"] = "1"
    else:
        env["GEARSYM_CACHE_DIR"] = str(cache)
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=cwd,
    )


ROOT = Path(__file__).resolve().parents[1]


def entries(cache: Path) -> list[Path]:
    return sorted(p for p in cache.iterdir() if p.is_dir()) if cache.exists() else []


@pytest.mark.parametrize(
    "args",
    [
        ("model", "--json"),
        ("model", "--shift", "2-3", "--friction-inputs"),
        ("ratios",),
    ],
)
def test_a_remembered_output_is_the_fresh_output(tmp_path, args):
    fresh = gearsym(None, *args)
    assert fresh.returncode == 0, fresh.stderr
    first = gearsym(tmp_path, *args)  # miss: derives and stores
    assert len(entries(tmp_path)) == 1
    second = gearsym(tmp_path, *args)  # hit
    for run in (first, second):
        assert (run.stdout, run.stderr, run.returncode) == (
            fresh.stdout,
            fresh.stderr,
            fresh.returncode,
        )


def test_a_hit_does_not_import_sympy(tmp_path):
    code = (
        "import sys, io, contextlib\n"
        "from gearsym.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    status = main(['model', '--json'])\n"
        "print(status, 'sympy' in sys.modules)\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("GEARSYM_")}
    env["GEARSYM_CACHE_DIR"] = str(tmp_path)
    runs = [
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120
        )
        for _ in range(2)
    ]
    assert [r.stdout.split() for r in runs] == [["0", "True"], ["0", "False"]], runs[1].stderr


def test_a_changed_description_is_a_miss_and_exit_1_with_its_message_is_replayed(tmp_path):
    cache = tmp_path / "cache"
    box = tmp_path / "box.toml"
    box.write_text(default_config_text())
    assert gearsym(cache, "ratios", "--json", str(box)).returncode == 0
    # the expected ratio of gear 2 no longer matches what the teeth give: exit 1, stderr names it
    box.write_text(default_config_text().replace("ratio = 3.243", "ratio = 3.300", 1))
    fresh = gearsym(None, "ratios", "--json", str(box))
    assert fresh.returncode == 1 and 'gear[name="2"].ratio' in fresh.stderr
    for _ in range(2):
        run = gearsym(cache, "ratios", "--json", str(box))
        assert (run.stdout, run.stderr, run.returncode) == (
            fresh.stdout,
            fresh.stderr,
            fresh.returncode,
        )
    assert len(entries(cache)) == 2


def test_options_are_part_of_the_key(tmp_path):
    a = gearsym(tmp_path, "model", "--json")
    b = gearsym(tmp_path, "model", "--json", "--with-wheel-acceleration")
    assert a.stdout != b.stdout
    assert "y_domega_C" in b.stdout or "wheel acceleration" in b.stdout
    assert len(entries(tmp_path)) == 2


def test_a_tampered_entry_is_not_trusted_and_not_replaced(tmp_path):
    fresh = gearsym(None, "ratios")
    gearsym(tmp_path, "ratios")
    (entry,) = entries(tmp_path)
    stored = entry / "output.json"
    data = json.loads(stored.read_text())
    data["stdout"] = "forged\n"
    stored.write_text(json.dumps(data))
    run = gearsym(tmp_path, "ratios")
    assert run.stdout == fresh.stdout and run.returncode == 0
    assert json.loads(stored.read_text())["stdout"] == "forged\n"  # the writer refused it


def test_errors_are_never_stored_and_no_cache_writes_nothing(tmp_path):
    missing = gearsym(tmp_path / "c1", "ratios", str(tmp_path / "absent.toml"))
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1
    bad = tmp_path / "bad.toml"
    bad.write_text("this is not toml = = =")
    assert gearsym(tmp_path / "c1", "model", str(bad)).returncode == 2
    assert entries(tmp_path / "c1") == []
    assert gearsym(tmp_path / "c2", "ratios", "--no-cache").returncode == 0
    assert entries(tmp_path / "c2") == []


def test_an_unwritable_cache_changes_nothing():
    # root ignores permissions: run as an unprivileged user, as tests/test_output_dir.py does
    from test_output_dir import _as_unprivileged_user

    prefix = _as_unprivileged_user()
    base = Path(tempfile.mkdtemp(prefix="gearsym-ro-cache-"))  # pytest's tmp_path is root-only
    try:
        base.chmod(0o555)
        env = {k: v for k, v in os.environ.items() if not k.startswith("GEARSYM_")}
        fresh = gearsym(None, "ratios")
        run = subprocess.run(
            [*prefix, sys.executable, "-m", "gearsym", "ratios"],
            capture_output=True,
            text=True,
            timeout=120,
            env={**env, "GEARSYM_CACHE_DIR": str(base / "cache")},
            cwd=ROOT,
        )
        assert (run.stdout, run.stderr, run.returncode) == (fresh.stdout, fresh.stderr, 0)
        assert not (base / "cache").exists()
    finally:
        base.chmod(0o755)
        shutil.rmtree(base, ignore_errors=True)


def test_cache_root_follows_the_environment(tmp_path):
    assert cache_root({"GEARSYM_NO_CACHE": "1", "GEARSYM_CACHE_DIR": "x"}) is None
    assert cache_root({"GEARSYM_CACHE_DIR": str(tmp_path)}) == tmp_path
    assert cache_root({"XDG_CACHE_HOME": str(tmp_path)}) == tmp_path / "gearsym"
    assert entry_key("ratios", {}, str(tmp_path / "absent.toml")) is None


SAVE_DURING_RUN = """
import sys
from pathlib import Path

import gearsym.symbolic.loader as loader
from gearsym import cli

box, saved = Path(sys.argv[1]), sys.argv[2]
real = loader.read_text


def save_then_read(path, shown=None):
    box.write_text(saved)  # the user saves the file while gearsym runs
    return real(path, shown)


loader.read_text = save_then_read
sys.exit(cli.main(["ratios", str(box)]))
"""


def test_a_file_saved_during_the_run_is_remembered_under_the_bytes_the_run_read(tmp_path):
    """The lookup reads the file before the run, the run reads it again: a save in between
    must not pair the old bytes' key with the new bytes' output (a wrong gear table would
    then replay "All ratios match", exit 0)."""
    cache, box = tmp_path / "cache", tmp_path / "box.toml"
    right = default_config_text()
    wrong = right.replace("ratio = 3.243", "ratio = 3.300", 1)
    box.write_text(wrong)
    env = {k: v for k, v in os.environ.items() if not k.startswith("GEARSYM_")}
    env["GEARSYM_CACHE_DIR"] = str(cache)
    during = subprocess.run(
        [sys.executable, "-c", SAVE_DURING_RUN, str(box), right],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert during.returncode == 0, during.stderr  # the run read the saved (right) table
    box.write_text(wrong)
    fresh = gearsym(None, "ratios", str(box))
    assert fresh.returncode == 1 and "1 gear(s) differ" in fresh.stdout
    cached = gearsym(cache, "ratios", str(box))
    assert (cached.stdout, cached.stderr, cached.returncode) == (
        fresh.stdout,
        fresh.stderr,
        fresh.returncode,
    )
    box.write_text(right)  # the entry the interrupted run stored serves the bytes it read
    assert len(entries(cache)) == 2
    replay = gearsym(cache, "ratios", str(box))
    assert replay.returncode == 0 and replay.stdout == during.stdout
    assert len(entries(cache)) == 2
