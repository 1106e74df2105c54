"""The child process that reads an MDF4 recording (:mod:`.mdf_read` runs it; its protocol
and checks are described there): ``python -m gearsym.validation.sim.mdf_child`` with the
request as JSON on stdin."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.sim.mdf_read import (
    CHILD_MEMORY_MAX,
    READ_FRAGMENT_BYTES,
    RECORDING_GROUP_BYTES_MAX,
    REFUSED_EXIT,
    _clip,
)
from gearsym.validation.sim.measurement import (
    RECORDING_CHANNELS_MAX,
    RECORDING_SAMPLES_MAX,
    Channel,
    ChannelMap,
    _few,
    analysis_grid,
    on_grid,
)


def _map_from_json(d: dict[str, Any]) -> ChannelMap:
    return ChannelMap(
        file=d["file"],
        sample_time=float(d["sample_time"]),
        channels=tuple(Channel(*c) for c in d["channels"]),
        time_channel=d["time_channel"],
        time_unit=d["time_unit"],
        time_offset=float(d["time_offset"]),
    )


def _check_group(mdf: Any, file: str, key: str, name: str, index: int) -> None:
    """The headers of channel group ``index`` promise no more than the limits allow, and every
    channel lies inside the group's record (checked before asammdf reads any data)."""
    group = mdf.groups[index]
    cg = group.channel_group
    v3 = str(mdf.version).startswith("3")
    cycles = int(cg.cycles_nr)
    record = int(cg.samples_byte_nr) + int(getattr(cg, "invalidation_bytes_nr", 0))
    if cycles > RECORDING_SAMPLES_MAX:
        raise GearsymError(
            file,
            key,
            f"channel {name!r}: its channel group declares {cycles} samples, more than "
            f"RECORDING_SAMPLES_MAX = {RECORDING_SAMPLES_MAX}",
        )
    if cycles * record > RECORDING_GROUP_BYTES_MAX:
        raise GearsymError(
            file,
            key,
            f"channel {name!r}: its channel group declares {cycles} records of {record} bytes, "
            f"more than {RECORDING_GROUP_BYTES_MAX >> 20} MiB of data",
        )
    for ch in group.channels:
        ctype = int(ch.channel_type)
        if v3:  # MDF 3: 0 a value, 1 the master; the offset in bits plus an extra byte offset
            start = int(ch.start_offset)
            byte_offset = start // 8 + int(getattr(ch, "additional_byte_offset", 0))
            bit_offset = start % 8
        else:
            byte_offset, bit_offset = int(ch.byte_offset), int(ch.bit_offset)
        if not v3 and ctype in (3, 6):  # virtual (master) channels: from the record index
            continue
        if not v3 and ctype not in (0, 2):
            if ch.name == name:
                raise GearsymError(
                    file, key, f"channel {name!r} is not a fixed-length numeric channel"
                )
            continue
        end = byte_offset + (bit_offset + int(ch.bit_count) + 7) // 8
        if int(ch.bit_count) > 64 or end > int(cg.samples_byte_nr):
            raise GearsymError(
                file,
                key,
                f"damaged MDF file: channel {ch.name!r} of the group of {name!r} lies outside "
                f"its record (byte offset {byte_offset}, {int(ch.bit_count)} bits, record "
                f"{int(cg.samples_byte_nr)} bytes)",
            )


def _child_read(request: dict[str, Any]) -> dict[str, np.ndarray]:
    import logging

    from asammdf import MDF

    logging.getLogger("asammdf").setLevel(logging.CRITICAL)
    file = request["file"]
    channel_map = _map_from_json(request["channel_map"])
    t_end = float(request["t_end"])
    grid = analysis_grid(t_end, channel_map.sample_time)
    try:
        mdf = MDF(request["source"])
    except MemoryError:
        raise
    except Exception as err:  # asammdf raises many kinds on a damaged file
        raise GearsymError(file, "", f"not a readable MDF file ({_clip(str(err))})") from None
    try:
        mdf.configure(read_fragment_size=READ_FRAGMENT_BYTES)
        count = sum(len(g.channels) for g in mdf.groups)
        if count > RECORDING_CHANNELS_MAX:
            raise GearsymError(
                file,
                "",
                f"{count} channels, more than RECORDING_CHANNELS_MAX = {RECORDING_CHANNELS_MAX}",
            )
        known = sorted(mdf.channels_db)
        out = {}
        for channel in channel_map.channels:
            key = f"measurement.channel.{channel.signal}.name"
            places = mdf.channels_db.get(channel.name)
            if not places:
                raise GearsymError(
                    file, key, f"no channel {channel.name!r} in the recording ({_few(known)})"
                )
            if len({g for g, _ in places}) > 1:
                raise GearsymError(
                    file,
                    key,
                    f"channel {channel.name!r} is in {len(places)} channel groups: ambiguous",
                )
            _check_group(mdf, file, key, channel.name, places[0][0])
            try:
                sig = mdf.get(channel.name, raw=False)
            except MemoryError:
                raise
            except Exception as err:  # e.g. a damaged data block
                raise GearsymError(
                    file, key, f"cannot read channel {channel.name!r}: {_clip(str(err))}"
                ) from None
            unit = (sig.unit or "").strip()
            if unit and unit != channel.unit:
                raise GearsymError(
                    file,
                    f"measurement.channel.{channel.signal}.unit",
                    f"the recording gives {channel.name!r} in {unit!r}, the channel map says "
                    f"{channel.unit!r}",
                )
            samples = np.asarray(sig.samples)
            if samples.dtype.kind not in "fiu" or samples.ndim != 1:
                raise GearsymError(
                    file, key, f"channel {channel.name!r} is not numeric ({samples.dtype})"
                )
            t = np.asarray(sig.timestamps, dtype=float)
            v = samples.astype(float)
            del sig, samples
            if len(t) != len(v):
                raise GearsymError(
                    file, key, f"channel {channel.name!r}: {len(v)} samples, {len(t)} times"
                )
            out[channel.signal] = on_grid(file, channel_map, channel, t, v, grid, t_end)
            del t, v
        return out
    finally:
        try:
            mdf.close()
        except Exception:  # a damaged file's cleanup may fail too: the answer is given
            pass


def _child_main() -> int:
    import resource

    try:
        resource.setrlimit(resource.RLIMIT_AS, (CHILD_MEMORY_MAX, CHILD_MEMORY_MAX))
    except (ValueError, OSError):
        pass
    request = json.loads(sys.stdin.read())
    try:
        values = _child_read(request)
    except GearsymError as err:
        print(json.dumps({"key": err.key, "reason": err.reason}))
        return REFUSED_EXIT
    except MemoryError:
        print(
            json.dumps(
                {
                    "key": "",
                    "reason": f"reading it needs more than {CHILD_MEMORY_MAX >> 30} GiB of "
                    "address space: a damaged or hostile file",
                }
            )
        )
        return REFUSED_EXIT
    except RecursionError:
        print(json.dumps({"key": "", "reason": "damaged MDF4 file (blocks link in a cycle)"}))
        return REFUSED_EXIT
    except Exception as err:  # anything else asammdf raises on a damaged file
        reason = f"not a readable MDF file ({type(err).__name__}: {_clip(str(err))})"
        print(json.dumps({"key": "", "reason": reason}))
        return REFUSED_EXIT
    np.savez(Path(request["out"]) / "values.npz", **values)
    return 0


if __name__ == "__main__":
    sys.exit(_child_main())
