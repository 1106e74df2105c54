"""Bench recordings are untrusted input (issue 26): no crash, no wrong success, bounded memory.

The contract (docs/limits.md): a bad recording ends in one line ``gearsym: FILE: ...`` on stderr,
exit code 2, no traceback, nothing written; reading one takes bounded memory whatever its
headers claim. Expected values come from that contract and from the stated limits
(validation/sim/measurement.py, validation/sim/mdf_read.py), never from the reader's output.
"""

from __future__ import annotations

import os
import random
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.sim import mdf_read
from gearsym.validation.sim import measurement as M

DATA = Path(M.__file__).resolve().parents[1] / "gearsym" / "data"
if not (DATA / "scenario_2_3_measured.toml").exists():  # installed: gearsym/data in the package
    import gearsym

    DATA = Path(gearsym.__file__).parent / "data"
SCENARIO = DATA / "scenario_2_3_measured.toml"
HEADER = "time,n_turbine,n_shaft2,n_wheel,Tq_input,p_K81,p_K38,p_B05,p_B06"
#: the scenario's channels (time_offset 12 s, window 0..1.5 s): plausible constant values
GOOD = {
    "n_turbine": 1900.0,
    "n_shaft2": 600.0,
    "n_wheel": 240.0,
    "Tq_input": 150.0,
    "p_K81": 15.0,
    "p_K38": 15.0,
    "p_B05": 0.0,
    "p_B06": 15.0,
}
UNIT = {"Tq_input": "Nm"} | {n: "bar" for n in GOOD if n.startswith("p_")}
#: The peak resident memory allowed to read a recording (parent and reader child each); a
#: fresh Python with numpy and gearsym imported takes ~75 MB, asammdf ~120 MB more (the readers
#: before took 1.25-2 GB).
MEMORY_BOUND_MB = 400


def gearsym_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, timeout=300
    )


def one_line_error(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    return lines[0]


@pytest.fixture(scope="module")
def cmap():
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.sim.scenario import load_scenario

    return load_scenario(load_description(None), SCENARIO).measurement


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> bytes:
    """A valid MDF4 recording, written by ``gearsym export-measurement``."""
    out = tmp_path_factory.mktemp("rec") / "rec.mf4"
    done = gearsym_cli(
        "export-measurement", "--scenario", str(SCENARIO), "--seed", "1", "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    return out.read_bytes()


def blocks(data: bytes, kind: bytes) -> list[tuple[int, int]]:
    """(start, start of the data section) of every MDF4 block ``##<kind>``: a block is
    ``##XX``, 4 reserved bytes, its length (u64) and link count (u64), the links, the data."""
    found = []
    start = data.find(b"##" + kind)
    while start >= 0:
        length, links = struct.unpack_from("<QQ", data, start + 8)
        if 24 + 8 * links <= length <= len(data) - start:
            found.append((start, start + 24 + 8 * links))
        start = data.find(b"##" + kind, start + 1)
    return found


def channel_field(data: bytes, index: int) -> int:
    """Where the byte offset (u32) of the ``index``-th channel block lies: CN data are
    channel type, sync type, data type, bit offset (one byte each), then the byte offset."""
    return blocks(data, b"CN")[index][1] + 4


def cycles_field(data: bytes) -> int:
    """Where the cycle count (u64) of the first channel group lies: CG data are the record
    id (u64), then the cycle count."""
    return blocks(data, b"CG")[0][1] + 8


def changed(data: bytes, pos: int, value: bytes) -> bytes:
    return data[:pos] + value + data[pos + len(value) :]


# ----------------------------------------------------------------------------- damaged MDF4

#: Corruptions that asammdf 8.8.28 does not survive in-process, found by changing the channel
#: byte offsets of the export: +4096 (SIGSEGV), +255 (glibc abort "corrupted size vs.
#: prev_size" / "malloc(): invalid size"), +128 on the master (a loop without end); and the
#: cleanup of a truncated file or of a data block whose length points past the end, which
#: printed "AttributeError: 'MDF4' object has no attribute '_file'" after the error.
CRASHES = {
    "channel byte offset +4096 (SIGSEGV)": lambda d: changed(
        d, channel_field(d, 1) + 1, bytes([d[channel_field(d, 1) + 1] + 0x10])
    ),
    "channel byte offset 255 (glibc abort)": lambda d: changed(d, channel_field(d, 2), b"\xff"),
    "master byte offset 255": lambda d: changed(d, channel_field(d, 0), b"\xff"),
    "channel byte offset 128 (no end)": lambda d: changed(d, channel_field(d, 1), b"\x80"),
    "data block length past the end": lambda d: changed(d, blocks(d, b"DT")[0][0] + 9, b"\x7f"),
    "truncated": lambda d: d[: len(d) // 2],
    "cycle count 10^15": lambda d: changed(d, cycles_field(d), struct.pack("<Q", 10**15)),
}


@pytest.mark.parametrize("damage", sorted(CRASHES))
def test_a_damaged_mdf4_is_one_line_and_writes_nothing(tmp_path, recording, damage):
    path = tmp_path / "bad.mf4"
    path.write_bytes(CRASHES[damage](recording))
    assert path.read_bytes() != recording
    line = one_line_error(
        gearsym_cli(
            "simulate",
            "--scenario",
            str(SCENARIO),
            "--measurement",
            str(path),
            "--out",
            str(tmp_path / "o"),
            "--no-plots",
        )
    )
    assert line.startswith(f"gearsym: {path}: "), line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "command",
    [
        ("estimate", "--filter", "ekf", "--no-plots"),
        ("sensitivity", "--no-plots"),
        ("fim", "--json"),
    ],
)
def test_every_command_reading_recordings_survives_the_crash_case(tmp_path, recording, command):
    """estimate, sensitivity and fim read recordings through the same reader: the SIGSEGV
    case is one line, exit 2, nothing written for them too."""
    path = tmp_path / "bad.mf4"
    path.write_bytes(CRASHES["channel byte offset +4096 (SIGSEGV)"](recording))
    out = () if command[0] == "fim" else ("--out", str(tmp_path / "o"))
    line = one_line_error(
        gearsym_cli(*command, "--scenario", str(SCENARIO), "--measurement", str(path), *out)
    )
    assert line.startswith(f"gearsym: {path}: ") and "outside its record" in line, line
    assert not (tmp_path / "o").exists()


def test_asammdf_alone_dies_on_the_regression_case(tmp_path, recording):
    """Why the reader runs in a child: asammdf, in-process, is killed by a signal on the
    +4096 byte offset (the regression case above), or loops without end (it reads freed
    memory: which of the two varies from run to run). Checked for the version it was found
    with; a later asammdf may read the file safely."""
    import asammdf

    if asammdf.__version__ != "8.8.28":
        pytest.skip(f"found with asammdf 8.8.28, installed {asammdf.__version__}")
    path = tmp_path / "bad.mf4"
    path.write_bytes(CRASHES["channel byte offset +4096 (SIGSEGV)"](recording))
    code = textwrap.dedent(
        f"""
        from asammdf import MDF
        mdf = MDF({str(path)!r})
        for name in {list(GOOD)!r}:
            mdf.get(name).samples.astype(float)
        """
    )
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=20)
    except subprocess.TimeoutExpired:
        return  # no end in 20 s (a good file reads in ~1 s)
    assert done.returncode < 0, (done.returncode, done.stderr[-300:])


@pytest.mark.parametrize(
    ("command", "seconds", "words"),
    [
        ("import os, signal; os.kill(os.getpid(), signal.SIGSEGV)", None, "SIGSEGV"),
        ("import os; os.abort()", None, "SIGABRT"),
        ("import sys; sys.exit('boom\\nsecond line')", None, "exit 1"),
        ("raise ValueError('a traceback')", None, "exit 1"),
        ("import time; time.sleep(30)", 0.5, "did not finish within 0.5 s"),
        ("print('not json'); raise SystemExit(3)", None, "exit 3"),
    ],
)
def test_a_dying_reader_child_is_one_line(
    tmp_path, recording, cmap, monkeypatch, command, seconds, words
):
    """Whatever becomes of the reader child (a signal, an exit code with a traceback on its
    stderr, no answer in time, a garbled answer): one GearsymError of one line."""
    monkeypatch.setattr(mdf_read, "CHILD_COMMAND", [sys.executable, "-c", command])
    if seconds is not None:
        monkeypatch.setattr(mdf_read, "CHILD_SECONDS_MAX", seconds)
    path = tmp_path / "rec.mf4"
    path.write_bytes(recording)
    with pytest.raises(GearsymError) as err:
        M.read_measurement(path, cmap, 1.5)
    assert "\n" not in str(err.value) and words in str(err.value), str(err.value)
    assert err.value.file == str(path)


@pytest.mark.slow
def test_random_single_byte_corruptions_never_crash(tmp_path, recording, cmap):
    """40 copies of the export with one byte changed (seed 26) in its block structure (after
    the data block: channel groups, channels, texts), and the crash cases: every read ends in
    a Measurement or in one GearsymError of one line, and this process survives. A Measurement
    of a damaged file still holds only finite, plausible values on the grid."""
    start = blocks(recording, b"DT")[0][0]
    end = start + struct.unpack_from("<Q", recording, start + 8)[0]
    rng = random.Random(26)
    cases = [CRASHES[k](recording) for k in sorted(CRASHES)]
    for _ in range(40):
        pos = rng.randrange(end, len(recording))
        cases.append(changed(recording, pos, bytes([rng.randrange(256)])))
    refused = 0
    for k, data in enumerate(cases):
        path = tmp_path / f"c{k}.mf4"
        path.write_bytes(data)
        try:
            m = M.read_measurement(path, cmap, 1.5)
        except GearsymError as err:
            assert "\n" not in str(err) and err.file == str(path), str(err)
            refused += 1
        else:
            for c in cmap.channels:
                v = m.values[c.signal]
                if c.is_input:
                    assert np.all(np.isfinite(v))
                assert np.all(np.abs(v[np.isfinite(v)]) <= M.plausible_max(c.quantity))
    assert refused >= len(CRASHES)


# ----------------------------------------------------------------------------- memory


def peak_memory(tmp_path: Path, recording: Path) -> tuple[str, float, float]:
    """Read ``recording`` with the scenario's channel map in a fresh process: its one-line
    outcome and the peak resident memory (MB) of that process and of its reader child."""
    code = textwrap.dedent(
        f"""
        import resource
        from gearsym.symbolic.errors import GearsymError
        from gearsym.symbolic.loader import load_description
        from gearsym.validation.sim.measurement import read_measurement
        from gearsym.validation.sim.scenario import load_scenario

        s = load_scenario(load_description(None), {str(SCENARIO)!r})
        try:
            read_measurement({str(recording)!r}, s.measurement, s.t_end)
            print("read")
        except GearsymError as err:
            print(err)
        # this process: the peak of its own memory map (VmHWM). getrusage's ru_maxrss keeps
        # the forking process's size across fork and exec, so under a large test worker it
        # reported the worker (537 MB), not the reader
        with open("/proc/self/status") as status:
            hwm = [line for line in status if line.startswith("VmHWM:")][0]
        print(int(hwm.split()[1]) / 1024)  # kB
        print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)  # kB on Linux
        """
    )
    # a clean environment and folder: nothing the suite's other tests set reaches the reader
    env = {k: os.environ[k] for k in ("PATH", "HOME", "LANG", "TMPDIR") if k in os.environ}
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    outcome, own, child = done.stdout.strip().splitlines()
    return outcome, float(own), float(child)


def mdf4(path: Path, n: int, compression: int = 2, version: str = "4.10") -> bytes:
    """An MDF4 of the scenario's channels, ``n`` samples of constant plausible values from
    12 s to 14 s of recording time (the window is 12..13.5 s), written by asammdf."""
    from asammdf import MDF, Signal

    t = 12.0 + np.arange(n) * (2.0 / n)
    mdf = MDF(version=version)
    mdf.append(
        [
            Signal(np.full(n, v, dtype=np.float32), t, name=name, unit=UNIT.get(name, "rpm"))
            for name, v in GOOD.items()
        ]
    )
    mdf.save(path, overwrite=True, compression=compression)
    mdf.close()
    return path.read_bytes()


def test_an_mdf4_header_claiming_1e8_samples_is_refused_before_reading(tmp_path):
    """A 1000-sample recording whose channel group claims 10^8 cycles (small on disk): refused
    from the header, naming the limit, and the reader's memory stays bounded."""
    path = tmp_path / "claims.mf4"
    data = mdf4(path, 1000)
    path.write_bytes(changed(data, cycles_field(data), struct.pack("<Q", 10**8)))
    outcome, own, child = peak_memory(tmp_path, path)
    assert "100000000 samples" in outcome and "RECORDING_SAMPLES_MAX" in outcome, outcome
    assert str(M.RECORDING_SAMPLES_MAX) in outcome
    assert own < MEMORY_BOUND_MB and child < MEMORY_BOUND_MB, (own, child)


def test_the_header_checks_pass_valid_mdf3_and_mdf4_files(tmp_path, cmap):
    """The checks before reading know both layouts (MDF 3: bit offset plus extra byte
    offset): the recorded constants come back on the grid, in SI units."""
    for version, name in (("3.30", "rec.mdf"), ("4.10", "rec.mf4")):
        path = tmp_path / name
        mdf4(path, 2000, compression=0, version=version)
        m = M.read_measurement(path, cmap, 1.5)
        assert m.values["omega_1"] == pytest.approx(1900 * np.pi / 30)  # rpm -> rad/s
        assert m.values["p_K38"] == pytest.approx(15e5)  # bar -> Pa


@pytest.mark.slow
def test_an_mdf4_at_the_sample_limit_reads_in_bounded_memory(tmp_path):
    """RECORDING_SAMPLES_MAX samples of 8 channels (40 MB of records, ~0.5 MB compressed)
    are read, within the memory bound; one sample more is refused from the header."""
    path = tmp_path / "limit.mf4"
    mdf4(path, M.RECORDING_SAMPLES_MAX)
    outcome, own, child = peak_memory(tmp_path, path)
    assert outcome == "read"
    assert own < MEMORY_BOUND_MB and child < MEMORY_BOUND_MB, (own, child)
    mdf4(path, M.RECORDING_SAMPLES_MAX + 1)
    outcome, own, child = peak_memory(tmp_path, path)
    assert "RECORDING_SAMPLES_MAX" in outcome, outcome


@pytest.mark.slow
def test_a_64_mib_csv_of_short_cells_is_refused_in_bounded_memory(tmp_path):
    """64 MiB of rows "1,1,...": 3.7 million rows, more than RECORDING_SAMPLES_MAX; the CSV is
    streamed, so the reader stops at the limit with bounded memory (it took 1.9 GB, 29x
    the file, when the file was read whole)."""
    path = tmp_path / "big.csv"
    row = ",".join(["1"] * 9) + "\n"
    with path.open("w") as f:
        f.write(HEADER + "\n")
        f.write(row * ((64 << 20) // len(row)))
    assert path.stat().st_size > (64 << 20) - 100
    outcome, own, child = peak_memory(tmp_path, path)
    assert f"more than RECORDING_SAMPLES_MAX = {M.RECORDING_SAMPLES_MAX} data rows" in outcome
    assert own < MEMORY_BOUND_MB, own


def test_csv_lines_and_columns_are_bounded(tmp_path, cmap):
    """A CSV without line breaks is refused at CSV_LINE_CHARS_MAX characters (not read
    whole), a header of more than RECORDING_CHANNELS_MAX columns is refused."""
    path = tmp_path / "one_line.csv"
    path.write_text("1," * (M.CSV_LINE_CHARS_MAX // 2 + 10))
    with pytest.raises(GearsymError) as err:
        M.read_measurement(path, cmap, 1.5)
    assert "CSV_LINE_CHARS_MAX" in err.value.reason
    path.write_text(HEADER + "," + ",".join(f"x{i}" for i in range(M.RECORDING_CHANNELS_MAX)))
    with pytest.raises(GearsymError) as err:
        M.read_measurement(path, cmap, 1.5)
    assert "RECORDING_CHANNELS_MAX" in err.value.reason


# ----------------------------------------------------------------------------- values


def csv_rows(path: Path, value_of=lambda name, t: GOOD[name]) -> Path:
    """A CSV recording of the scenario's channels every 10 ms over 12.0..13.6 s."""
    lines = [HEADER]
    for t in np.round(np.arange(12.0, 13.6001, 0.01), 2):
        lines.append(",".join([f"{t:.2f}", *(str(value_of(n, t)) for n in GOOD)]))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(
    ("name", "value", "accepted"),
    [
        # 5000 rad/s = 47 746 rpm (PLAUSIBLE_MAX["speed"])
        ("n_turbine", 1e300, False),
        ("n_turbine", 47_700.0, True),
        ("n_turbine", 47_800.0, False),
        ("n_wheel", -1e20, False),
        # 10 000 N*m
        ("Tq_input", 9_999.0, True),
        ("Tq_input", 10_001.0, False),
        # 100 bar = 1e7 Pa
        ("p_K38", 99.0, True),
        ("p_K38", 1e300, False),
    ],
)
def test_one_absurd_sample_is_refused(tmp_path, cmap, name, value, accepted):
    """One sample at 12.5 s (scenario time 0.5 s) beyond its quantity's plausible bound."""
    path = csv_rows(tmp_path / "rec.csv", lambda n, t: value if (n, t) == (name, 12.5) else GOOD[n])
    if accepted:
        M.read_measurement(path, cmap, 1.5)
        return
    with pytest.raises(GearsymError) as err:
        M.read_measurement(path, cmap, 1.5)
    signal_name = next(c.signal for c in cmap.channels if c.name == name)
    assert err.value.key == f"measurement.channel.{signal_name}", str(err.value)
    assert "PLAUSIBLE_MAX" in err.value.reason and "t = 0.5 s" in err.value.reason


def test_an_absurd_speed_through_estimate_is_one_line(tmp_path):
    path = csv_rows(
        tmp_path / "rec.csv", lambda n, t: 1e300 if (n, t) == ("n_turbine", 12.5) else GOOD[n]
    )
    line = one_line_error(
        gearsym_cli(
            "estimate",
            "--filter",
            "ekf",
            "--scenario",
            str(SCENARIO),
            "--measurement",
            str(path),
            "--out",
            str(tmp_path / "o"),
            "--no-plots",
        )
    )
    assert "measurement.channel.omega_1" in line and "PLAUSIBLE_MAX" in line, line
    assert not (tmp_path / "o").exists()


def test_estimate_refuses_a_recording_without_a_finite_speed(tmp_path):
    """Every n_turbine cell empty (NaN): the filter would receive no measurement of omega_1
    and print its initial values as estimates; refused in one line instead."""
    path = csv_rows(tmp_path / "rec.csv", lambda n, t: "" if n == "n_turbine" else GOOD[n])
    line = one_line_error(
        gearsym_cli(
            "estimate",
            "--filter",
            "ekf",
            "--scenario",
            str(SCENARIO),
            "--measurement",
            str(path),
            "--out",
            str(tmp_path / "o"),
            "--no-plots",
        )
    )
    assert line.startswith(f"gearsym: {path}: measurement.channel.omega_1: "), line
    assert "no finite sample" in line
    assert not (tmp_path / "o").exists()


def test_require_names_the_first_signal_without_a_finite_sample(tmp_path, cmap):
    """A speed channel without a finite sample is refused only when required (by the
    filter); a speed that is NaN in part of the window is a dropout and passes."""
    path = csv_rows(tmp_path / "rec.csv", lambda n, t: "" if n == "n_wheel" else GOOD[n])
    m = M.read_measurement(path, cmap, 1.5)  # without require: a dropout over the window
    assert np.all(np.isnan(m.values["omega_C"]))
    with pytest.raises(GearsymError) as err:
        M.read_measurement(path, cmap, 1.5, require=["omega_1", "omega_C"])
    assert err.value.key == "measurement.channel.omega_C"
    path = csv_rows(
        tmp_path / "rec.csv", lambda n, t: "" if n == "n_wheel" and t > 13.0 else GOOD[n]
    )
    m = M.read_measurement(path, cmap, 1.5, require=["omega_C"])
    assert np.isnan(m.values["omega_C"][-1]) and np.isfinite(m.values["omega_C"][0])


def test_the_plausible_grade_is_the_scenarios_bound():
    from gearsym.validation.sim.scenario import GRADE_MAX

    assert M.PLAUSIBLE_MAX["grade"] == GRADE_MAX
