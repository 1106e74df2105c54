"""The description's optional ``[control]`` table (symbolic/control_calibration.py): the
TCU's nominal actuator, its shift controller's tuning and its adaptation, with defaults when
absent and one-line refusals naming file and key."""

from __future__ import annotations

import re

import pytest
from gearsym.symbolic.control_calibration import default_control
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.package_data import data_file
from gearsym.symbolic.loader import load_description

#: The issue's stated defaults, typed here from the issue (not read from the code).
STATED = {
    ("actuator", "dead_time"): (0.010, "s"),
    ("actuator", "time_constant"): (0.030, "s"),
    ("actuator", "fill_time"): (0.100, "s"),
    ("actuator", "fast_fill_pressure"): (3.0e5, "Pa"),
    ("actuator", "return_spring"): (0.8e5, "Pa"),
    ("shift", "torque_phase"): (0.15, "s"),
    ("shift", "inertia_phase"): (0.35, "s"),
    ("shift", "fill_hold"): (0.2e5, "Pa"),
    ("shift", "slip_k_p"): (400.0, "Pa*s/rad"),
    ("shift", "slip_t_i"): (0.2, "s"),
    ("shift", "lockup_slip"): (5.0, "rad/s"),
    ("shift", "off_going_margin"): (1.2, "1"),
    ("adaptation", "fill_step"): (0.020, "s"),
    ("adaptation", "fill_limit"): (0.100, "s"),
    ("adaptation", "pressure_step"): (500.0, "Pa"),
    ("adaptation", "pressure_limit"): (3.0e4, "Pa"),
}


def _builtin_text() -> str:
    return data_file("thesis_9speed.toml").read_text(encoding="utf-8")


def _without_control() -> str:
    """The built-in description with its ``[control.*]`` tables (the file's last) cut off."""
    text = _builtin_text()
    cut = text.index("[control.actuator]")
    return text[: text.rindex("\n\n", 0, cut)] + "\n"


def test_defaults_when_the_table_is_absent():
    d = parse_description(_without_control(), "box.toml")
    for (section, key), (value, unit) in STATED.items():
        entry = d.control.entry(section, key)
        assert (entry.value, entry.unit) == (value, unit), (section, key)
        assert entry.source.startswith("gearsym default (assumed")
        assert d.control.si(section, key) == value
    assert d.control == default_control()


def test_the_builtin_description_states_the_table_with_sources():
    d = load_description()
    for (section, key), (value, unit) in STATED.items():
        entry = d.control.entry(section, key)
        assert (entry.value, entry.unit) == (value, unit), (section, key)
        assert entry.source.startswith("assumed ("), (section, key)
    table = d.control.to_dict()
    assert set(table) == {"actuator", "shift", "adaptation"}
    assert table["shift"]["slip_k_p"] == {
        "value": 400.0,
        "unit": "Pa*s/rad",
        "source": d.control.entry("shift", "slip_k_p").source,
    }


def test_a_partial_table_keeps_the_other_defaults():
    text = _without_control() + (
        '\n[control.actuator]\nfill_time = { value = 0.12, unit = "s", source = "test" }\n'
    )
    d = parse_description(text, "box.toml")
    assert d.control.entry("actuator", "fill_time").value == 0.12
    assert d.control.entry("actuator", "fill_time").source == "test"
    assert d.control.si("actuator", "dead_time") == 0.010
    assert d.control.file == "box.toml"


@pytest.mark.parametrize(
    ("table", "key", "reason"),
    [
        (
            '[control.actuator]\nfill_time = { value = 0.1, unit = "ms", source = "x" }',
            "control.actuator.fill_time.unit",
            "expected 's', got 'ms'",
        ),
        (
            '[control.shift]\nslip_kp = { value = 1.0, unit = "Pa*s/rad", source = "x" }',
            "control.shift.slip_kp",
            "unknown",
        ),
        (
            '[control.valve]\ndead_time = { value = 0.01, unit = "s", source = "x" }',
            "control.valve",
            "unknown",
        ),
        (
            '[control.adaptation]\nfill_step = { value = 0.02, unit = "s", source = " " }',
            "control.adaptation.fill_step.source",
            "must say where the value comes from",
        ),
        (
            '[control.adaptation]\nfill_step = { value = 0.02, unit = "s" }',
            "control.adaptation.fill_step.source",
            "missing required key",
        ),
        (
            '[control.shift]\nlockup_slip = { value = -5.0, unit = "rad/s", source = "x" }',
            "control.shift.lockup_slip.value",
            "must be positive",
        ),
        (
            '[control.actuator]\nreturn_spring = { value = 4.0e5, unit = "Pa", source = "x" }',
            "control.actuator.fast_fill_pressure",
            "must lie above return_spring",
        ),
    ],
)
def test_a_bad_table_is_refused_in_one_line(table, key, reason):
    with pytest.raises(GearsymError) as err:
        parse_description(_without_control() + "\n" + table + "\n", "box.toml")
    text = str(err.value)
    assert "\n" not in text and text.startswith("box.toml: "), text
    assert re.search(rf"\b{re.escape(key)}\b", text) and reason in text, text
