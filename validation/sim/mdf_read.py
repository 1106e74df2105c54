"""Reading an MDF4 recording in a child process: a damaged file must not take gearsym down.

asammdf trusts the block structure of the file: a channel's byte offset changed by one byte
makes it read outside its buffers (SIGSEGV, a glibc abort or an endless loop, asammdf
8.8.28), a channel group's cycle count of 10^8 makes it allocate gigabytes. So
:func:`read_mdf_on_grid` runs ``python -m gearsym.validation.sim.mdf_child`` (:mod:`.mdf_child`)
and

* the child checks the headers before it reads any data: every channel of a group that is read
  lies inside the group's record (byte offset + bits ≤ record bytes), the cycle count is at
  most :data:`~gearsym.validation.sim.measurement.RECORDING_SAMPLES_MAX` and the group's record
  data at most :data:`RECORDING_GROUP_BYTES_MAX`, the file at most
  :data:`~gearsym.validation.sim.measurement.RECORDING_CHANNELS_MAX` channels;
* the child reads one channel at a time and resamples it onto the analysis grid at once
  (:func:`~gearsym.validation.sim.measurement.on_grid`): what it returns are grid arrays
  (≤ 5000 samples each), never the recording;
* its address space is limited (:data:`CHILD_MEMORY_MAX`) and its time
  (:data:`CHILD_SECONDS_MAX`): a death by a signal, a non-zero exit, running out of memory or
  time becomes one line ``gearsym: FILE: <reason>``, exit code 2.

Protocol: the request is JSON on stdin; the child writes ``values.npz`` into the request's
folder and exits 0, or prints ``{"key": ..., "reason": ...}`` on stdout and exits
:data:`REFUSED_EXIT` for a :class:`GearsymError`.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.errors import GearsymError

#: Largest record data of one channel group read (cycles × record bytes, after
#: decompression): the file limit, so a compressed file cannot unpack to more than an
#: uncompressed one could hold.
RECORDING_GROUP_BYTES_MAX = 256 << 20

#: The child's address-space limit (RLIMIT_AS): Python, numpy and asammdf take ~0.5 GB of
#: address space (not of memory) before reading; this is a backstop, the header checks above
#: bound what a valid-looking file can ask for.
CHILD_MEMORY_MAX = 2 << 30

#: The child's time limit: a one-shift bench file reads in about a second.
CHILD_SECONDS_MAX = 120.0

#: asammdf's fragment size: the data are read 16 MiB at a time, not 256 MiB (its default).
READ_FRAGMENT_BYTES = 16 << 20

REFUSED_EXIT = 3

#: The child's command line (the tests put a crashing or hanging child here).
CHILD_COMMAND = [sys.executable, "-m", "gearsym.validation.sim.mdf_child"]


def read_mdf_on_grid(
    source: Path, file: str, channel_map: Any, t_end: float
) -> dict[str, np.ndarray]:
    """Per mapped signal, its channel of the MDF4 ``source`` resampled onto the analysis grid
    (SI units), read in a child process (module docstring)."""
    import importlib.util

    if importlib.util.find_spec("asammdf") is None:
        raise GearsymError(
            file, "", "reading MDF4 needs asammdf: pip install 'gearsym[mdf]' (or use a CSV)"
        )
    with tempfile.TemporaryDirectory(prefix="gearsym-mdf-") as folder:
        request = {
            "source": str(source.resolve()),
            "file": file,
            "channel_map": _map_to_json(channel_map),
            "t_end": t_end,
            "out": folder,
        }
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        try:
            done = subprocess.run(
                CHILD_COMMAND,
                input=json.dumps(request),
                capture_output=True,
                text=True,
                timeout=CHILD_SECONDS_MAX,
                env=env,
                cwd=folder,  # not the user's folder: `-m` puts the working folder on sys.path
                check=False,
            )
        except subprocess.TimeoutExpired:
            raise GearsymError(
                file,
                "",
                f"the MDF reader (asammdf) did not finish within {CHILD_SECONDS_MAX:g} s: "
                "a damaged file",
            ) from None
        if done.returncode == REFUSED_EXIT:
            try:
                answer = json.loads(done.stdout)
                raise GearsymError(file, str(answer["key"]), str(answer["reason"]))
            except (ValueError, KeyError, TypeError):
                pass
        if done.returncode < 0:
            try:
                name = signal.Signals(-done.returncode).name
            except ValueError:
                name = f"signal {-done.returncode}"
            raise GearsymError(
                file,
                "",
                f"the MDF reader (asammdf) crashed on it ({name}): a damaged or hostile file "
                "(its block structure points outside its data)",
            )
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or ["no message"])[-1]
            raise GearsymError(
                file,
                "",
                f"the MDF reader (asammdf) failed (exit {done.returncode}): {_clip(last)}",
            )
        with np.load(Path(folder) / "values.npz", allow_pickle=False) as npz:
            return {c.signal: np.array(npz[c.signal]) for c in channel_map.channels}


def _clip(text: str, n: int = 200) -> str:
    text = " ".join(text.split())
    return text if len(text) <= n else text[: n - 3] + "..."


def _map_to_json(channel_map: Any) -> dict[str, Any]:
    return {
        "file": channel_map.file,
        "sample_time": channel_map.sample_time,
        "time_channel": channel_map.time_channel,
        "time_unit": channel_map.time_unit,
        "time_offset": channel_map.time_offset,
        "channels": [
            [c.signal, c.name, c.unit, c.quantity, c.gain, c.offset] for c in channel_map.channels
        ],
    }
