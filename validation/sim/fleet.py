"""A fleet of vehicles: the truths an estimator is judged on, apart from what it knows.

A TCU is calibrated once (the description and its ``[estimator]`` table) and then meets every
vehicle of a fleet: heavier or lighter, on other grades, with clutches whose friction moved
with oil temperature and wear, with an engine whose torque model is off by a few percent and
valves whose pressure is off by some mbar. A fleet file states those spreads; each run of an
evaluation draws one vehicle from it (:meth:`Fleet.draw`), the reference simulates that
vehicle (:func:`truth_world`), and the filter is handed only what the TCU would have: the
commanded pressures and the torque it is told (:func:`told_inputs`), never the draw.

The file::

    [fleet]
    name = "default"
    source = "what the fleet stands for"
    m_veh = { dist = "uniform", low = 1500.0, high = 2400.0, unit = "kg", source = "..." }
    input_torque_gain = { dist = "normal", mean = 1.0, sd = 0.02, unit = "1", source = "..." }
    zeta = { value = 0.0, unit = "rad", source = "..." }          # fixed

    [fleet.factor]      # relative tolerances: the truth = factor x the description's value
    vehicle.r_dyn = { dist = "normal", mean = 1.0, sd = 0.01, unit = "1", source = "..." }
    inertia = { dist = "uniform", low = 0.95, high = 1.05, unit = "1", source = "..." }

Every entry names its unit and its source; an unknown name, a distribution that reaches
outside the quantity's plausible range, or a wrong unit is refused in one line naming the file
and the key.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.description import SECTION_UNITS, GearboxDescription, Quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.input_files import parse_toml, read_text
from gearsym.symbolic.io.package_data import data_file
from gearsym.symbolic.io.table_reader import TableReader
from gearsym.validation.sim.scenario import Profile, Scenario
from gearsym.validation.sim.tooth_wheel import ToothWheel

__all__ = [
    "DEFAULT_FLEET",
    "DESCRIPTION_QUANTITIES",
    "EFFECTS",
    "FLEET_QUANTITIES",
    "Distribution",
    "Fleet",
    "FleetDraw",
    "TruthWorld",
    "R_DYN_FACTOR",
    "load_fleet",
    "told_inputs",
    "truth_world",
    "wheel_side_mass",
]

#: The shipped fleet (``--fleet`` without a file name uses it).
DEFAULT_FLEET = "fleet_default.toml"

#: Quantities of the description a fleet may draw (their unit and plausible range are their
#: records', :mod:`gearsym.symbolic.parameters`): the mass, and a constant road grade (added to
#: a scenario's ``[grade]`` profile).
DESCRIPTION_QUANTITIES: tuple[str, ...] = ("m_veh", "zeta")

#: The fleet's own quantities: unit, plausible range, and what the draw does to the truth. A
#: ``mu_scale_<ELEMENT>`` entry scales one element's μ map (times ``mu_scale``).
EFFECTS: dict[str, tuple[str, tuple[float, float], str]] = {
    "mu_scale": ("1", (0.2, 5.0), "every element's μ map scaled (oil temperature, wear)"),
    "input_torque_gain": (
        "1",
        (0.2, 5.0),
        "the true input torque T_In over the one the TCU is told",
    ),
    "engine_torque_gain": ("1", (0.2, 5.0), "the true engine torque over its torque model"),
    "engine_torque_offset": (
        "N*m",
        (-1000.0, 1000.0),
        "added to the true engine torque (accessories, friction)",
    ),
    "e_machine_torque_gain": (
        "1",
        (0.2, 5.0),
        "the true e-machine torque over its commanded torque",
    ),
    "pressure_gain": ("1", (0.2, 5.0), "the true apply pressure over the commanded one"),
    "pressure_offset": (
        "Pa",
        (-5.0e5, 5.0e5),
        "added to the true pressure of an applied element (valve, return spring) at each knot "
        "of the commanded profile where it is above zero; linear between the knots",
    ),
    "speed_sensor_teeth": (
        "1",
        (1.0, 1000.0),
        "every measured speed read from a toothed wheel of this many teeth (rounded) as the "
        "pitch over the last tooth period (validation/sim/tooth_wheel.py) instead of with the "
        "Gaussian noise of (3.26); speed_sensor_teeth_<speed> (omega_C, ...) for one sensor; "
        "needs speed_sensor_timer",
    ),
    "speed_sensor_timer": (
        "s",
        (1.0e-9, 1.0e-3),
        "the tooth-period counter's resolution: each period rounded to it",
    ),
    "speed_sensor_latency": (
        "s",
        (0.0, 0.05),
        "from a tooth edge to the TCU sample that may use it (capture, transport, task phase)",
    ),
    "fill_time_error": (
        "s",
        (-1.0, 1.0),
        "added to the clutch's true fill time over the TCU's nominal [control.actuator] "
        "fill_time (validation/sim/actuator.py: ClutchActuator.from_draw); the true fill time "
        "must stay positive",
    ),
}

#: Every name a ``[fleet]`` table may draw, beside ``mu_scale_<ELEMENT>``.
FLEET_QUANTITIES: tuple[str, ...] = (*DESCRIPTION_QUANTITIES, *EFFECTS)

_FACTOR_RANGE = (0.2, 5.0)


def _unit_and_range(name: str) -> tuple[str, tuple[float, float]]:
    from gearsym.symbolic.parameters import record

    if name in EFFECTS:
        return EFFECTS[name][0], EFFECTS[name][1]
    r = record(name)
    low, high = r.bounds or (None, None)
    return r.unit, (-math.inf if low is None else low, math.inf if high is None else high)


#: A normal distribution's support is taken as mean ± this many σ for the range check (a draw
#: beyond has probability 6e-7 and is clipped to it).
_NORMAL_REACH = 5.0

DISTRIBUTIONS = ("uniform", "normal")

#: ``[fleet.factor]`` keys beside ``<section>.<key>``: every shaft's and planet's inertia.
FACTOR_INERTIA = "inertia"


@dataclass(frozen=True)
class Distribution:
    """One fleet entry: fixed (``kind`` "fixed", ``a`` the value), uniform on [a, b] or normal
    with mean a and σ b (clipped to a ± 5 σ)."""

    kind: str
    a: float
    b: float = 0.0
    unit: str = "1"
    source: str = ""

    def support(self) -> tuple[float, float]:
        if self.kind == "fixed":
            return self.a, self.a
        if self.kind == "uniform":
            return self.a, self.b
        return self.a - _NORMAL_REACH * self.b, self.a + _NORMAL_REACH * self.b

    def sample(self, rng: np.random.Generator) -> float:
        if self.kind == "fixed":
            return self.a
        if self.kind == "uniform":
            return float(rng.uniform(self.a, self.b))
        return float(np.clip(rng.normal(self.a, self.b), *self.support()))

    @property
    def mean(self) -> float:
        return (self.a + self.b) / 2 if self.kind == "uniform" else self.a

    @property
    def sd(self) -> float:
        if self.kind == "fixed":
            return 0.0
        return (self.b - self.a) / math.sqrt(12.0) if self.kind == "uniform" else self.b

    def to_dict(self) -> dict[str, Any]:
        if self.kind == "fixed":
            shape: dict[str, Any] = {"value": self.a}
        elif self.kind == "uniform":
            shape = {"dist": "uniform", "low": self.a, "high": self.b}
        else:
            shape = {"dist": "normal", "mean": self.a, "sd": self.b}
        return {**shape, "unit": self.unit, "source": self.source}


@dataclass(frozen=True)
class FleetDraw:
    """One vehicle of a fleet: the drawn value per entry name (factors as
    ``factor.<section>.<key>`` / ``factor.inertia``), and the seed that drew it."""

    seed: int
    values: tuple[tuple[str, float], ...]

    def get(self, name: str, default: float) -> float:
        return dict(self.values).get(name, default)

    def to_dict(self) -> dict[str, Any]:
        return {"seed": self.seed, **dict(self.values)}


@dataclass(frozen=True)
class Fleet:
    """A parsed fleet file: the entries by name (factors as ``factor.<section>.<key>``)."""

    name: str
    file: str
    source: str
    entries: tuple[tuple[str, Distribution], ...]

    def draw(self, seed: int) -> FleetDraw:
        """The vehicle of run ``seed``. Each entry has its own random stream, keyed by the
        seed and the entry's name: adding or changing one entry leaves the others' draws as
        they were, and the speed noise of the run (its own stream) is untouched."""
        values = []
        for name, dist in self.entries:
            rng = np.random.default_rng([seed, 2, zlib.crc32(name.encode())])
            values.append((name, dist.sample(rng)))
        return FleetDraw(seed, tuple(values))

    def without_speed_sensors(self, command: str) -> Fleet:
        """This fleet, for a ``command`` that does not read tooth-wheel speed sensors: a
        one-line error when it draws any (they would be silently ignored)."""
        sensors = [name for name, _ in self.entries if name.startswith("speed_sensor_")]
        if sensors:
            raise GearsymError(
                self.file,
                f"fleet.{sensors[0]}",
                f"tooth-wheel speed sensors are read by gearsym estimate --fleet only; "
                f"gearsym {command} would ignore them (use a fleet without them)",
            )
        return self

    def fixed(self, name: str, value: float, where: str) -> Fleet:
        """The same fleet with entry ``name`` fixed at ``value`` (its other entries draw as
        before: each has its own stream). ``where`` names the option in a refusal."""
        names = [n for n, _ in self.entries]
        if name not in names:
            raise GearsymError(
                self.file, where, f"no fleet entry {name!r} (entries: {', '.join(names)})"
            )
        dist = dict(self.entries)[name]
        entries = tuple(
            (n, Distribution("fixed", value, 0.0, dist.unit, f"fixed by {where}"))
            if n == name
            else (n, d)
            for n, d in self.entries
        )
        return replace(self, name=f"{self.name}, {name} = {value:g}", entries=entries)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "file": self.file,
            "source": self.source,
            "entries": {name: dist.to_dict() for name, dist in self.entries},
        }


def _distribution(entry: TableReader, unit: str, low: float, high: float) -> Distribution:
    source = entry.string("source")
    given_unit = entry.string("unit")
    if "value" in entry.data:
        value = entry.number("value")
        assert value is not None
        dist = Distribution("fixed", value, unit=given_unit, source=source)
    else:
        kind = entry.string("dist")
        if kind == "uniform":
            a, b = entry.number("low"), entry.number("high")
            assert a is not None and b is not None
            if not a < b:
                raise entry.fail("high", f"must be above low ({a:g}), got {b:g}")
        elif kind == "normal":
            a, b = entry.number("mean"), entry.number("sd")
            assert a is not None and b is not None
            if not b > 0:
                raise entry.fail("sd", f"must be positive, got {b:g}")
        else:
            raise entry.fail(
                "dist", f"expected one of {', '.join(DISTRIBUTIONS)} (or a fixed value = X)"
            )
        dist = Distribution(kind, a, b, given_unit, source)
    entry.reject_unknown()
    if given_unit != unit:
        raise entry.fail("unit", f"expected {unit!r}, got {given_unit!r}")
    if not source.strip():
        raise entry.fail("source", "must say where the range comes from (or 'assumed')")
    lo, hi = dist.support()
    if lo < low or hi > high:
        reach = " (mean ± 5 sd)" if dist.kind == "normal" else ""
        raise entry.fail(
            "dist" if dist.kind != "fixed" else "value",
            f"reaches [{lo:g}, {hi:g}]{reach}, outside the plausible [{low:g}, {high:g}] {unit}",
        )
    return dist


def _base_fleet(extends: str, file: str, d: GearboxDescription, depth: int) -> Fleet:
    """The fleet ``extends`` names: "default" (the shipped fleet) or a file relative to the
    extending one's folder."""
    if depth >= 8:
        raise GearsymError(file, "fleet.extends", "more than 8 fleets extend each other")
    if extends == "default":
        return parse_fleet(
            read_text(data_file(DEFAULT_FLEET), f"<built-in {DEFAULT_FLEET}>"),
            f"<built-in {DEFAULT_FLEET}>",
            d,
            _depth=depth + 1,
        )
    path = Path(file).parent / extends
    if not path.is_file():
        raise GearsymError(file, "fleet.extends", f"no fleet file {str(path)!r} (or 'default')")
    return parse_fleet(read_text(path, str(path)), str(path), d, _depth=depth + 1)


def parse_fleet(text: str, file: str, d: GearboxDescription, _depth: int = 0) -> Fleet:
    """A fleet file's text, checked against the description (element names, quantities).
    ``extends = "default"`` (or a fleet file's path relative to this one) starts from that
    fleet's entries; this file's entries replace those of the same name and add the rest."""
    root = TableReader(file, parse_toml(text, file), "")
    table = root.table("fleet")
    name = table.string("name", required=False, default=Path(file).stem)
    source = table.string("source", required=False, default="")
    extends = table.string("extends", required=False, default="")
    elements = {e.name for e in d.shift_elements if not e.one_way}
    per_sensor = {f"{SENSOR_TEETH}_{speed}" for speed in measured_speeds(d)}
    entries: list[tuple[str, Distribution]] = []
    for key in list(table.data):
        if key in ("name", "source", "factor", "extends"):
            continue
        if key in FLEET_QUANTITIES:
            unit, (low, high) = _unit_and_range(key)
        elif key.startswith("mu_scale_") and key.removeprefix("mu_scale_") in elements:
            unit, (low, high) = _unit_and_range("mu_scale")
        elif key in per_sensor:
            unit, (low, high) = _unit_and_range(SENSOR_TEETH)
        else:
            known = [
                *FLEET_QUANTITIES,
                *(f"mu_scale_{e}" for e in sorted(elements)),
                *sorted(per_sensor),
            ]
            raise table.fail(key, f"unknown fleet quantity (known: {', '.join(known)})")
        dist = _distribution(table.table(key), unit, low, high)
        fill_time = d.control.si("actuator", "fill_time")
        if key == "fill_time_error" and not dist.support()[0] > -fill_time:
            raise table.table(key).fail(
                "dist" if dist.kind != "fixed" else "value",
                f"reaches {dist.support()[0]:g} s: the true fill time (the description's "
                f"{fill_time:g} s plus the error) must stay positive",
            )
        entries.append((key, dist))
    factor = table.table("factor", required=False)
    for section in list(factor.data):
        if section == FACTOR_INERTIA:
            entries.append(
                (f"factor.{section}", _distribution(factor.table(section), "1", *_FACTOR_RANGE))
            )
            continue
        if section not in SECTION_UNITS:
            raise factor.fail(
                section,
                f"expected {FACTOR_INERTIA} or a description section "
                f"({', '.join(SECTION_UNITS)}) with its keys",
            )
        sub = factor.table(section)
        present = getattr(d, section)
        for key in list(sub.data):
            if key not in present:
                raise sub.fail(
                    key,
                    f"the description has no [{section}] {key} "
                    f"(it has: {', '.join(sorted(present)) or 'none'})",
                )
            entries.append(
                (f"factor.{section}.{key}", _distribution(sub.table(key), "1", *_FACTOR_RANGE))
            )
        sub.reject_unknown()
    factor.reject_unknown()
    table.reject_unknown()
    root.reject_unknown()
    if extends:
        base = _base_fleet(extends, file, d, _depth)
        own = {key for key, _ in entries}
        entries = [*(e for e in base.entries if e[0] not in own), *entries]
    if not entries:
        raise table.fail("fleet", "draws nothing: give at least one entry")
    drawn = {key for key, _ in entries}
    sensors = {key for key in drawn if key.startswith("speed_sensor_")}
    teeth = {key for key in sensors if key.startswith(SENSOR_TEETH)}
    if sensors and "speed_sensor_timer" not in sensors:
        raise table.fail("speed_sensor_timer", "a tooth-wheel speed sensor needs its timer")
    if sensors and SENSOR_TEETH not in teeth and teeth != per_sensor:
        missing = sorted(per_sensor - teeth)[0] if teeth else SENSOR_TEETH
        raise table.fail(
            missing,
            f"every measured speed needs its teeth: give {SENSOR_TEETH} (all) or "
            f"{SENSOR_TEETH}_<speed> for each of {', '.join(sorted(per_sensor))}",
        )
    return Fleet(name, file, source, tuple(sorted(entries)))


def load_fleet(d: GearboxDescription, path: str | Path | None = None) -> Fleet:
    """The fleet file ``path`` (``None``: the shipped :data:`DEFAULT_FLEET`)."""
    file = str(path) if path is not None else f"<built-in {DEFAULT_FLEET}>"
    source = Path(path) if path is not None else data_file(DEFAULT_FLEET)
    return parse_fleet(read_text(source, file), file, d)


# ---------------------------------------------------------------------------------------------
# One draw as the truth
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TruthWorld:
    """One vehicle of the fleet as the reference simulates it: the truth's description
    (mass, grade, tolerances), the true inputs (torques and pressures after their errors) and
    the factor on each element's μ map."""

    description: GearboxDescription
    scenario: Scenario
    mu_scale: Mapping[str, float] = field(default_factory=dict)
    draw: FleetDraw | None = None


def _scaled(q: Quantity, factor: float) -> Quantity:
    return Quantity(q.value * factor, q.unit, f"{q.source}; x {factor:.6g} (fleet draw)")


@dataclass(frozen=True)
class Actuators:
    """What the vehicle's engine, electric machine and valves really give for what the TCU
    commands (a fleet draw's tolerances): T_eng = g_in g_eng T_eng,cmd + g_in T_offset,
    T_em = g_in g_em T_em,cmd, p = max(g_p p_cmd + p_offset, 0) where p_cmd > 0 (a valve
    commanded shut stays shut)."""

    engine_gain: float = 1.0
    engine_offset: float = 0.0
    e_machine_gain: float = 1.0
    pressure_gain: float = 1.0
    pressure_offset: float = 0.0

    @classmethod
    def from_draw(cls, draw: FleetDraw) -> Actuators:
        values = dict(draw.values)
        gain = values.get("input_torque_gain", 1.0)
        return cls(
            engine_gain=gain * values.get("engine_torque_gain", 1.0),
            engine_offset=gain * values.get("engine_torque_offset", 0.0),
            e_machine_gain=gain * values.get("e_machine_torque_gain", 1.0),
            pressure_gain=values.get("pressure_gain", 1.0),
            pressure_offset=values.get("pressure_offset", 0.0),
        )

    def engine(self, commanded: Any) -> Any:
        return self.engine_gain * commanded + self.engine_offset

    def e_machine(self, commanded: Any) -> Any:
        return self.e_machine_gain * commanded

    def pressure(self, commanded: Any) -> Any:
        return np.where(
            commanded > 0,
            np.maximum(self.pressure_gain * commanded + self.pressure_offset, 0.0),
            0.0,
        )


def truth_description(
    d: GearboxDescription, draw: FleetDraw, constant_grade: bool = True
) -> GearboxDescription:
    """The calibration ``d`` as the vehicle ``draw`` really is: its mass, its grade (when the
    grade is ``constant_grade``, not a profile), every factor on the description's quantities
    and the inertias."""
    values = dict(draw.values)
    vehicle = dict(d.vehicle)
    sections = {"vehicle": vehicle, "drivetrain": dict(d.drivetrain), "friction": dict(d.friction)}
    for name, factor in values.items():
        parts = name.split(".")
        if parts[0] == "factor" and len(parts) == 3:
            sections[parts[1]][parts[2]] = _scaled(sections[parts[1]][parts[2]], factor)
    if "m_veh" in values:
        vehicle["m_veh"] = Quantity(values["m_veh"], "kg", "fleet draw")
    zeta = values.get("zeta")
    if zeta is not None and constant_grade:
        vehicle["zeta"] = Quantity(zeta, "rad", "fleet draw")
    truth = replace(
        d,
        vehicle=sections["vehicle"],
        drivetrain=sections["drivetrain"],
        friction=sections["friction"],
    )
    inertia = values.get(f"factor.{FACTOR_INERTIA}")
    if inertia is not None:
        truth = truth.with_inertias(lambda q: _scaled(q, inertia))
    return truth


def mu_scales(d: GearboxDescription, draw: FleetDraw) -> dict[str, float]:
    """The truth's factor on each friction element's μ map (common and per element)."""
    values = dict(draw.values)
    common = values.get("mu_scale", 1.0)
    return {
        e.name: common * values.get(f"mu_scale_{e.name}", 1.0)
        for e in d.shift_elements
        if not e.one_way
    }


def truth_world(d: GearboxDescription, scenario: Scenario, draw: FleetDraw) -> TruthWorld:
    """The vehicle ``draw`` on ``scenario``: what the reference simulates. ``d`` and
    ``scenario`` are the calibration's and the commanded inputs; the returned world is the
    truth (the filter never sees it)."""
    truth = truth_description(d, draw, constant_grade=scenario.grade is None)
    actuators = Actuators.from_draw(draw)
    pressure = {
        e: Profile(profile.time, actuators.pressure(np.asarray(profile.value, dtype=float)))
        for e, profile in scenario.pressure.items()
    }
    zeta = dict(draw.values).get("zeta")
    grade = scenario.grade
    if zeta is not None and grade is not None:
        grade = Profile(grade.time, grade.value + zeta)
    true_scenario = replace(
        scenario,
        engine=Profile(scenario.engine.time, actuators.engine(scenario.engine.value)),
        e_machine=Profile(scenario.e_machine.time, actuators.e_machine(scenario.e_machine.value)),
        pressure=pressure,
        grade=grade,
    )
    return TruthWorld(truth, true_scenario, mu_scales(d, draw), draw)


#: The fleet's name of the tooth count; ``speed_sensor_teeth_<speed>`` (``<speed>`` a measured
#: speed such as ``omega_C``) gives one sensor its own wheel.
SENSOR_TEETH = "speed_sensor_teeth"


def measured_speeds(d: GearboxDescription) -> tuple[str, ...]:
    """The speeds a TCU of ``d`` measures: every measured shaft's and the wheel's (3.31)."""
    from gearsym.symbolic import naming

    return (*(naming.speed(s) for s in d.measured_shafts), naming.WHEEL_SPEED)


def speed_sensor(draw: FleetDraw, speed: str) -> ToothWheel | None:
    """The vehicle's tooth-wheel sensor of the measured ``speed``: its own
    ``speed_sensor_teeth_<speed>`` wheel, else the common ``speed_sensor_teeth``; ``None`` when
    the fleet draws no sensor (the speeds then carry the Gaussian noise of (3.26))."""
    values = dict(draw.values)
    teeth = values.get(f"{SENSOR_TEETH}_{speed}", values.get(SENSOR_TEETH))
    if teeth is None:
        return None
    return ToothWheel(
        teeth=max(int(round(teeth)), 1),
        timer=values["speed_sensor_timer"],
        latency=values.get("speed_sensor_latency", 0.0),
    )


def told_inputs(
    d: GearboxDescription, scenario: Scenario, t: np.ndarray, names: Sequence[str]
) -> dict[str, np.ndarray]:
    """What the TCU is told of the inputs ``names`` on its grid ``t``: T_In from the torque it
    commands (engine model plus e-machine, the scenario as written), each F_N from the
    commanded pressure times the calibration's piston area. Names that are not such inputs
    (the mode flags) are left out."""
    from gearsym.symbolic import naming

    element_names = [e.name for e in d.shift_elements]
    forces = {
        naming.normal_force(naming.element_short_name(e.name, element_names)): e
        for e in d.shift_elements
        if e.a_piston is not None
    }
    out: dict[str, np.ndarray] = {}
    for name in names:
        if name == naming.INPUT_TORQUE:
            out[name] = np.array([scenario.input_torque(float(v)) for v in t])
        elif name in forces:
            e = forces[name]
            assert e.a_piston is not None
            profile = scenario.pressure.get(e.name)
            values = np.zeros(len(t)) if profile is None else np.interp(t, *_knots(profile))
            out[name] = values * e.a_piston.value
    return out


def _knots(profile: Profile) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(profile.time, dtype=float), np.asarray(profile.value, dtype=float)


#: The fleet's draw of the tyres' dynamic radius, as a factor on the calibration's r_dyn.
R_DYN_FACTOR = "factor.vehicle.r_dyn"


def wheel_side_mass(m_veh: float, r_dyn_factor: float) -> float:
    """The vehicle's mass as the wheel's speed sees it through the calibration's r_dyn:
    m_veh (r_dyn / r_dyn,cal)². The wheel equation (2.49) has m_veh r_dyn² beside I_wheel
    and the TCU measures wheel and shaft speeds, not the vehicle's speed, so a filter with the
    calibration's r_dyn identifies this product, not m_veh: a tyre 1 % larger reads as 2 %
    more mass. It is the inertia a shift's inertia-phase feed-forward needs."""
    return m_veh * r_dyn_factor**2
