"""The background figure worker of `gearsym run` (validation/drawing/figures.py: Background)."""

from __future__ import annotations

import os
import time

import pytest
from gearsym.validation.drawing.figures import Background


def _write(path, text):
    path.write_text(text)


def _fail():
    raise ValueError("broken figure")


def _sleep_then_write(path):
    time.sleep(30)
    path.write_text("too late")


def test_a_child_writes_its_file_before_wait_returns(tmp_path):
    with Background() as worker:
        worker.submit("a", _write, tmp_path / "a.txt", "drawn")
        worker.submit("b", _write, tmp_path / "b.txt", "also")
        worker.wait()
        assert (tmp_path / "a.txt").read_text() == "drawn"
        assert (tmp_path / "b.txt").read_text() == "also"


def test_a_failed_child_is_an_error_naming_the_job(tmp_path, capfd):
    with pytest.raises(RuntimeError, match="drawing failed: Figures X"):
        with Background() as worker:
            worker.submit("Figures X", _fail)
    assert "broken figure" in capfd.readouterr().err  # the child's traceback, on stderr


def test_an_error_in_the_caller_kills_the_children(tmp_path):
    start = time.perf_counter()
    with pytest.raises(KeyError):
        with Background() as worker:
            worker.submit("slow", _sleep_then_write, tmp_path / "late.txt")
            pids = [pid for pid, _ in worker._children]
            raise KeyError("the analysis failed")
    assert time.perf_counter() - start < 10  # not waited for
    for pid in pids:  # reaped: no such child any more
        with pytest.raises(ChildProcessError):
            os.waitpid(pid, os.WNOHANG)
    assert not (tmp_path / "late.txt").exists()
