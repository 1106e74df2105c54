"""What the TCU's estimators assume (thesis chapter 4), read from a description's optional
``[estimator]`` table: the filter's prior (the start z0 and P0 of (4.3)) and its tuning (the
random-walk intensities of (4.1) and the model-error intensities of the states).

This is calibration, never the truth: a TCU is flashed with one prior for a whole fleet of
vehicles, so the prior's mean is a stated number (for the mass, a mean between the empty
and the loaded vehicle), not the value of the vehicle the filter will meet. Where the table is
silent the defaults of :mod:`gearsym.symbolic.parameters` apply: the prior's mean is the
description's own value of the parameter and its σ the record's stated default.

The table::

    [estimator]
    tuned_on = "what the tuning below was chosen on (fleet, scenario, seeds)"
    [estimator.prior]      # mean optional (default: the description's value), sd required
    m_veh = { mean = 1950.0, sd = 300.0, unit = "kg", source = "..." }
    mu    = { sd = 0.015, unit = "1", source = "..." }    # every mu_<element>
    [estimator.random_walk]    # q_p of (4.1), unit^2/s
    mu = { value = 4.0e-3, unit = "1/s", source = "..." }
    [estimator.model_error]    # q_x of a state of the filter's model, unit^2/s
    omega_1 = { value = 6.0, unit = "rad^2/s^3", source = "..." }
    [estimator.model_error_augmented]    # the same, of a filter that estimates more (k_ss, gain)
    phi = { value = 4.7e-5, unit = "rad^2/s", source = "..." }
    [estimator.model_error_map_scale]    # the same, with mu_model = "map_scale" besides
    phi = { value = 4.7e-5, unit = "rad^2/s", source = "..." }
    in_gear = { value = 0.1, unit = "1", source = "..." }  # factor while no element slides
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.parameters import RECORDS, is_mu, record

__all__ = [
    "AUGMENTED_STATES",
    "CONSIDERED_STATES",
    "INERTIA_FACTOR",
    "INPUT_TORQUE_GAIN",
    "ENGINE_TORQUE_GAIN",
    "MODEL_ERROR_AUGMENTED",
    "MODEL_ERROR_MAP_SCALE",
    "MU_MODELS",
    "MU_SCALE",
    "PRIOR_NAMES",
    "DAMPING",
    "DAMPING_FACTOR",
    "IN_GEAR",
    "IN_GEAR_SETTLE",
    "STIFFNESS",
    "STIFFNESS_FACTOR",
    "VALVE_GAIN",
    "VALVE_OFFSET",
    "FILL_TIME_ERROR",
    "EstimatorCalibration",
    "Prior",
    "Tuning",
    "parse_estimator_table",
]

#: How the filter models an element's μ (``[estimator] mu_model``): "random_walk", the
#: thesis' (4.1): μ itself a random-walk state; "map_scale": μ = s · μ_map(p, T_oil, |Δω|), the
#: calibration's μ map at the commanded pressure and the filter's own slip estimate, times a
#: scale s per element that is the random-walk state (oil temperature, wear).
MU_MODELS: tuple[str, ...] = ("random_walk", "map_scale")

#: The scale state's name in the tables (the state keeps the element's ``mu_<E>`` name).
MU_SCALE = "mu_scale"

#: The valve's pressure offset (Pa) as a filter state (the adaptive-control study's estimator:
#: every applied element's effective pressure off the TCU's nominal valve by one constant).
VALVE_OFFSET = "valve_offset"

#: The valves' gain on the commanded pressure as a filter state (a shift filter over a fleet,
#: ``--params ...,valve_gain``): the effective pressure over the commanded one, every element
#: alike (one valve type, one supply). Beside μ it multiplies the same F_N, so one shift
#: cannot tell them apart: carried, it puts the valves' tolerance into μ's σ.
VALVE_GAIN = "valve_gain"

#: Default random walk of the valves' gain (1/s): none within a shift (assumed).
VALVE_GAIN_RANDOM_WALK = 0.0

#: The on-coming piston's fill time off the calibration's (s): the adaptive-control study's
#: belief over shifts (not a filter state: the replay of each shift estimates it).
FILL_TIME_ERROR = "fill_time_error"

#: The side shafts' stiffness as a factor on the description's k_ss (a filter state over a
#: drive: the twist's frequency is seen in every speed, and a stiffness off the calibration's
#: is otherwise read as mass, the vehicle's inertia being in that frequency too).
STIFFNESS_FACTOR = "k_ss_factor"

#: The side shafts' damping as a factor on the description's d_ss: the twist's decay after
#: every torque step of a shift. On the default fleet's tuning vehicles its ±20 % was the
#: largest tolerance outside the filter's model in the gears (the third gear's NEES/dof 3.0
#: with a near-zero model error, 1.15 with the damping exact), so a filter without it needs
#: model error that widens every predicted speed.
DAMPING_FACTOR = "d_ss_factor"

#: The gain on the input torque a shift filter may estimate as a state (``--params
#: ...,input_torque_gain``): the true T_In over the one the TCU is told (the engine's torque
#: model, the e-machine's command), the fleet's name for the same quantity.
INPUT_TORQUE_GAIN = "input_torque_gain"

#: Default random walk of the input-torque gain (1/s): the engine's and the e-machine's errors
#: differ, so the gain of their sum moves with the torque split, by about 0.02 over the
#: built-in 2-3 shift's 1.5 s for a 5 % engine error (assumed).
INPUT_TORQUE_GAIN_RANDOM_WALK = 3.0e-4

#: The engine's torque gain a filter over a whole drive estimates as a state: the true engine
#: torque over the torque model's (the fleet's ``engine_torque_gain``). Over a drive the torque
#: split moves (electric launch, recuperation, the engine at its limit with the machine
#: boosting), so the engine's gain and the vehicle's mass are seen in different combinations;
#: within one shift the split is fixed and only the gain of their sum exists
#: (:data:`INPUT_TORQUE_GAIN`).
ENGINE_TORQUE_GAIN = "engine_torque_gain"

#: Default random walk of the engine's torque gain (1/s): a torque model's error does not
#: drift within a drive but with fuel, altitude and temperature, about 0.4 % over a 30 min
#: drive (assumed).
ENGINE_TORQUE_GAIN_RANDOM_WALK = 1.0e-8

#: A common factor on every rotating inertia of the gearbox (shafts and planets) a shift filter
#: may estimate as a state (``--params ...,inertia_factor``): the true inertias over the
#: design values. The twist's frequency holds the stiffness against these inertias, the speed
#: phase the element's μ against them, so a filter that takes them as exact claims a stiffness
#: and a μ more certain than they are; with the factor a state their tolerance is in its model.
INERTIA_FACTOR = "inertia_factor"

#: Default random walk of the inertia factor (1/s): none, a part's inertia does not drift.
INERTIA_FACTOR_RANDOM_WALK = 0.0

#: The names ``[estimator.prior]`` may give: the unmeasured state φ (side-shaft twist) and
#: every quantity whose record states a prior (``mu`` stands for every ``mu_<element>``).
PRIOR_NAMES: tuple[str, ...] = (
    "phi",
    *(r.key for r in RECORDS if r.prior_sigma is not None),
    MU_SCALE,
    VALVE_OFFSET,
    FILL_TIME_ERROR,
    STIFFNESS_FACTOR,
    DAMPING_FACTOR,
    INPUT_TORQUE_GAIN,
    ENGINE_TORQUE_GAIN,
    INERTIA_FACTOR,
    VALVE_GAIN,
)

#: The names ``[estimator.random_walk]`` may give (``mu``: every ``mu_<element>``; ``mu_scale``:
#: every element's map scale under ``mu_model = "map_scale"``).
RANDOM_WALK_NAMES: tuple[str, ...] = (
    *(r.key for r in RECORDS if r.random_walk is not None),
    MU_SCALE,
    VALVE_OFFSET,
    STIFFNESS_FACTOR,
    DAMPING_FACTOR,
    INPUT_TORQUE_GAIN,
    ENGINE_TORQUE_GAIN,
    INERTIA_FACTOR,
    VALVE_GAIN,
)

#: The states a shift filter carries as consider states (Schmidt): their tolerance enters its
#: covariance (and so the σ of what they are confounded with), but no measurement corrects
#: them. The valves' offset and gain: on the default fleet's tuning vehicles (seeds
#: 100000-100099) a corrected offset ended the 2-3 with an RMSE of 5 500 Pa (its prior's σ is
#: 6 000) while claiming σ 3 700 (coverage 79 %): μ's dependence on slip, which the filter's
#: random walk follows late, was read as the valve's.
CONSIDERED_STATES: tuple[str, ...] = (VALVE_OFFSET, VALVE_GAIN)

#: The fixed parameter a shift filter may estimate as a state beside the thesis' (4.1)
#: (``gearsym estimate --fleet --params ...,k_ss``): the side shafts' stiffness, whose prior and
#: random walk are the stiffness factor's times the calibration's value.
STIFFNESS = "k_ss"

#: The side shafts' damping a shift filter may estimate as a state (``--params ...,d_ss``), its
#: prior and random walk the damping factor's times the calibration's d_ss.
DAMPING = "d_ss"

#: The states a shift filter over a fleet may carry beside the thesis' (4.1).
AUGMENTED_STATES: tuple[str, ...] = (
    STIFFNESS,
    DAMPING,
    INPUT_TORQUE_GAIN,
    INERTIA_FACTOR,
    VALVE_OFFSET,
    VALVE_GAIN,
)

#: The table of the model-error intensities of a filter that estimates more than the thesis'
#: parameters (any of :data:`AUGMENTED_STATES`), beside ``model_error`` (the thesis' filter):
#: the stiffness tolerance and the torque error are then in its model, so its twist and speeds
#: are tuned on their own (with every one of them a state); a state it does not name takes
#: ``model_error``'s value.
MODEL_ERROR_AUGMENTED = "model_error_augmented"

#: The table of the model-error intensities of such a filter whose μ states are scales on the
#: calibration's μ map (``mu_model = "map_scale"``): the map's slip dependence is then in its
#: model, so what its speeds and twist must stand for differs again; tuned on its own, a state
#: it does not name takes :data:`MODEL_ERROR_AUGMENTED`'s value.
MODEL_ERROR_MAP_SCALE = "model_error_map_scale"

#: The states beside the shaft speeds ``omega_<shaft>`` that ``[estimator.model_error]`` may
#: name: the side-shaft twist and the wheel speed (2.43, 2.44).
MODEL_ERROR_NAMES: tuple[str, ...] = ("phi", "omega_C")

#: The entry of a model-error table that is no state: a factor (unit "1", default 1) on that
#: table's intensities of the model's physical states over a prediction interval in which no
#: element of the shift slides (the gears before and after it). The model's errors are largest
#: while a clutch slides (its friction's map, its force); in a gear the elastic drivetrain
#: model leaves little, and one white model error for both widens every predicted speed of the
#: gears (the fleet evaluation's consistency per phase shows it).
IN_GEAR = "in_gear"
#: The entries of a model-error table that are not a state's intensity.
IN_GEAR_ENTRIES = ("in_gear", "in_gear_settle")
#: A model-error table's sub-table of per-shift in-gear entries (``shift."2-3"``).
SHIFT_KEY = "shift"
#: A model-error table's settling time (s): the in-gear factor acts only once the filter's
#: last mode switch lies this long behind; a lock-up or an opening is a torque step that rings
#: the drivetrain's torsional modes, which the rigid shift model does not have, for tens of
#: milliseconds (0: from the switch on).
IN_GEAR_SETTLE = "in_gear_settle"

#: Units of the prior entries that have no record (φ, the μ-map scale).
_PRIOR_UNITS = {
    "phi": "rad",
    MU_SCALE: "1",
    VALVE_OFFSET: "Pa",
    FILL_TIME_ERROR: "s",
    STIFFNESS_FACTOR: "1",
    DAMPING_FACTOR: "1",
    INPUT_TORQUE_GAIN: "1",
    ENGINE_TORQUE_GAIN: "1",
    INERTIA_FACTOR: "1",
    VALVE_GAIN: "1",
}

#: Default priors of the entries without a record: φ untwisted, σ 0.05 rad; the μ-map scale 1 (the
#: calibration's map), σ 0.2; the valve's offset 0 (the nominal valve), σ 6 000 Pa (uniform within
#: ±100 mbar); the fill time's error 0, σ 0.029 s (production fill times uniform within ±50 ms); the
#: side shafts' stiffness factor 1, σ 0.058 (uniform within ±10 %: production spread and
#: temperature); their damping factor 1, σ 0.115 (uniform within ±20 %); the input-torque gain and
#: the engine's torque gain 1, σ 0.029 (the engine's torque model uniform within ±5 %); the inertia
#: factor 1, σ 0.017 (inertias uniform within ±3 % of the design values); the valves' gain 1,
#: σ 0.017 (±3 %); all assumed.
_DEFAULT_PRIORS = {
    "phi": (0.0, 0.05),
    MU_SCALE: (1.0, 0.2),
    VALVE_OFFSET: (0.0, 6.0e3),
    FILL_TIME_ERROR: (0.0, 0.029),
    STIFFNESS_FACTOR: (1.0, 0.058),
    DAMPING_FACTOR: (1.0, 0.115),
    INPUT_TORQUE_GAIN: (1.0, 0.029),
    ENGINE_TORQUE_GAIN: (1.0, 0.029),
    INERTIA_FACTOR: (1.0, 0.017),
    VALVE_GAIN: (1.0, 0.017),
}

#: Default random walk of the valve's offset (Pa²/s): constant within a drive, allowed to
#: drift by about 50 Pa per root second (oil temperature; assumed).
VALVE_OFFSET_RANDOM_WALK = 2.5e3

#: Default random walk of the side shafts' stiffness factor (1/s): constant within a drive but
#: for temperature, about 0.001 per root second (assumed; it also keeps the factor from
#: becoming certain of a value that lumps other errors of the twist's frequency).
STIFFNESS_FACTOR_RANDOM_WALK = 1.0e-6

#: Default random walk of the side shafts' damping factor (1/s): as the stiffness's, constant
#: within a drive but for temperature (assumed).
DAMPING_FACTOR_RANDOM_WALK = 1.0e-6

#: Default random walk of the μ-map scale (1/s): it moves with oil temperature and wear over
#: minutes, not within a shift (assumed).
MU_SCALE_RANDOM_WALK = 1.0e-3


@dataclass(frozen=True)
class Prior:
    """One entry of the filter's prior: ``mean`` (``None``: the description's value of the
    parameter) and standard deviation ``sd``, both in the quantity's unit."""

    sd: float
    mean: float | None = None
    source: str = ""


@dataclass(frozen=True)
class Tuning:
    """One stated intensity (unit²/s) with where it comes from."""

    value: float
    unit: str
    source: str


@dataclass(frozen=True)
class EstimatorCalibration:
    """The ``[estimator]`` table: priors by name, random-walk and model-error intensities, and
    what the tuning was chosen on. Empty (every default) when the description has no table."""

    prior: tuple[tuple[str, Prior], ...] = ()
    random_walk: tuple[tuple[str, Tuning], ...] = ()
    model_error: tuple[tuple[str, Tuning], ...] = ()
    #: ``[estimator.model_error_augmented]``: the intensities of a filter that estimates more
    #: than the thesis' parameters (:data:`MODEL_ERROR_AUGMENTED`)
    model_error_augmented: tuple[tuple[str, Tuning], ...] = ()
    #: ``[estimator.model_error_map_scale]``: the same with the μ states map scales
    #: (:data:`MODEL_ERROR_MAP_SCALE`)
    model_error_map_scale: tuple[tuple[str, Tuning], ...] = ()
    #: a model-error table's ``[... .shift."<from>-<to>"]`` sub-tables: (table, shift, its
    #: :data:`IN_GEAR_ENTRIES`), which override the table's own for that shift's filter
    in_gear_by_shift: tuple[tuple[str, str, tuple[tuple[str, Tuning], ...]], ...] = ()
    tuned_on: str = ""
    #: :data:`MU_MODELS`
    mu_model: str = "random_walk"
    #: the description file, for errors raised when a name meets a model
    file: str = field(default="", compare=False)

    def prior_of(self, name: str, nominal: float | None) -> tuple[float, float]:
        """(mean, σ) of the state ``name``'s prior: the table's entry (``mu`` for any
        ``mu_<element>``), else the record's default σ (relative to ``nominal`` where the record
        says so) around ``nominal``. A one-line error when neither gives a σ or a mean."""
        key = "mu" if is_mu(name) else name
        given = dict(self.prior).get(key)
        if given is None and key in _DEFAULT_PRIORS:
            return _DEFAULT_PRIORS[key]
        if given is None and key in (STIFFNESS, DAMPING) and nominal is not None:
            mean_factor, sd_factor = self._stated_prior(
                STIFFNESS_FACTOR if key == STIFFNESS else DAMPING_FACTOR
            )
            return float(nominal) * mean_factor, abs(float(nominal)) * sd_factor
        mean = given.mean if given is not None and given.mean is not None else nominal
        if mean is None:
            raise GearsymError(
                self.file or "estimator",
                f"estimator.prior.{key}",
                f"no mean for {name}: state one (the description has no value for it)",
            )
        if given is not None:
            return float(mean), given.sd
        try:
            r = record(name)
        except KeyError:
            r = None
        if r is None or r.prior_sigma is None:
            raise GearsymError(
                self.file or "estimator",
                f"estimator.prior.{key}",
                f"no prior for {name}: state {{ mean = ..., sd = ... }}",
            )
        sd = r.prior_sigma * abs(float(mean)) if r.prior_relative else r.prior_sigma
        return float(mean), float(sd)

    def _stated_prior(self, key: str) -> tuple[float, float]:
        """(mean, σ) of a prior entry without a record: the table's, else the default
        (a stated σ without a mean keeps the default mean)."""
        default = _DEFAULT_PRIORS[key]
        given = dict(self.prior).get(key)
        if given is None:
            return default
        return (default[0] if given.mean is None else float(given.mean)), given.sd

    def scale_prior(self) -> tuple[float, float]:
        """(mean, σ) of every element's μ-map scale (``mu_model = "map_scale"``)."""
        return self._stated_prior(MU_SCALE)

    def scale_random_walk(self) -> float:
        """q of every element's μ-map scale (1/s)."""
        given = dict(self.random_walk).get(MU_SCALE)
        return MU_SCALE_RANDOM_WALK if given is None else given.value

    def valve_offset_prior(self) -> tuple[float, float]:
        """(mean, σ) of the valve's pressure offset state (Pa)."""
        return self._stated_prior(VALVE_OFFSET)

    def valve_offset_random_walk(self) -> float:
        """q of the valve's pressure offset state (Pa²/s)."""
        given = dict(self.random_walk).get(VALVE_OFFSET)
        return VALVE_OFFSET_RANDOM_WALK if given is None else given.value

    def fill_time_error_prior(self) -> tuple[float, float]:
        """(mean, σ) of the fill time's error against the calibration's (s)."""
        return self._stated_prior(FILL_TIME_ERROR)

    def stiffness_factor_prior(self) -> tuple[float, float]:
        """(mean, σ) of the side shafts' stiffness factor state."""
        return self._stated_prior(STIFFNESS_FACTOR)

    def damping_factor_prior(self) -> tuple[float, float]:
        """(mean, σ) of the side shafts' damping factor state."""
        return self._stated_prior(DAMPING_FACTOR)

    def stiffness_factor_random_walk(self) -> float:
        """q of the side shafts' stiffness factor state (1/s)."""
        given = dict(self.random_walk).get(STIFFNESS_FACTOR)
        return STIFFNESS_FACTOR_RANDOM_WALK if given is None else given.value

    def damping_factor_random_walk(self) -> float:
        """q of the side shafts' damping factor state (1/s)."""
        given = dict(self.random_walk).get(DAMPING_FACTOR)
        return DAMPING_FACTOR_RANDOM_WALK if given is None else given.value

    def intensities(self) -> dict[str, float]:
        """Every stated intensity by state name (``mu``: every μ state), the overrides
        :func:`gearsym.symbolic.estimators.ekf.augmented_model` takes."""
        return {
            name: t.value
            for name, t in (*self.random_walk, *self.model_error)
            if name
            not in (
                IN_GEAR,
                IN_GEAR_SETTLE,
                MU_SCALE,
                VALVE_OFFSET,
                VALVE_GAIN,
                STIFFNESS_FACTOR,
                DAMPING_FACTOR,
                INPUT_TORQUE_GAIN,
                ENGINE_TORQUE_GAIN,
                INERTIA_FACTOR,
            )
        }

    def input_torque_gain_random_walk(self) -> float:
        """q of the input-torque gain state (1/s)."""
        given = dict(self.random_walk).get(INPUT_TORQUE_GAIN)
        return INPUT_TORQUE_GAIN_RANDOM_WALK if given is None else given.value

    def engine_torque_gain_prior(self) -> tuple[float, float]:
        """(mean, σ) of the engine's torque gain state (a filter over a drive)."""
        return self._stated_prior(ENGINE_TORQUE_GAIN)

    def engine_torque_gain_random_walk(self) -> float:
        """q of the engine's torque gain state (1/s)."""
        given = dict(self.random_walk).get(ENGINE_TORQUE_GAIN)
        return ENGINE_TORQUE_GAIN_RANDOM_WALK if given is None else given.value

    def inertia_factor_random_walk(self) -> float:
        """q of the inertia factor state (1/s)."""
        given = dict(self.random_walk).get(INERTIA_FACTOR)
        return INERTIA_FACTOR_RANDOM_WALK if given is None else given.value

    def valve_gain_random_walk(self) -> float:
        """q of the valves' gain state (1/s)."""
        given = dict(self.random_walk).get(VALVE_GAIN)
        return VALVE_GAIN_RANDOM_WALK if given is None else given.value

    def intensities_augmented(self) -> dict[str, float]:
        """The model-error intensities of a filter that estimates any of
        :data:`AUGMENTED_STATES`, by state name (``[estimator.model_error_augmented]``, empty
        when the table is absent)."""
        return {
            name: t.value
            for name, t in self.model_error_augmented
            if name not in (IN_GEAR, IN_GEAR_SETTLE)
        }

    def intensities_map_scale(self) -> dict[str, float]:
        """The model-error intensities of such a filter whose μ states are map scales, by state
        name (``[estimator.model_error_map_scale]``, empty when the table is absent)."""
        return {
            name: t.value
            for name, t in self.model_error_map_scale
            if name not in (IN_GEAR, IN_GEAR_SETTLE)
        }

    def in_gear_factor(self, tables: Sequence[str], shift: str | None = None) -> float:
        """The :data:`IN_GEAR` factor of a filter whose intensities come from ``tables`` (model
        -error table names, each over the one before, as the intensities): the last one that
        states it, its ``shift`` sub-table over the table's own; else 1 (the same
        intensities in a gear as in a shift)."""
        return self._in_gear_entry(IN_GEAR, tables, shift, 1.0)

    def in_gear_settle(self, tables: Sequence[str], shift: str | None = None) -> float:
        """The :data:`IN_GEAR_SETTLE` time (s) of a filter whose intensities come from
        ``tables``, as :meth:`in_gear_factor` (0 where none states it)."""
        return self._in_gear_entry(IN_GEAR_SETTLE, tables, shift, 0.0)

    def _in_gear_entry(
        self, name: str, tables: Sequence[str], shift: str | None, default: float
    ) -> float:
        value = default
        for kind in tables:
            given = dict(getattr(self, kind)).get(name)
            if given is not None:
                value = given.value
            for table, own_shift, entries in self.in_gear_by_shift:
                if table == kind and own_shift == shift and name in dict(entries):
                    value = dict(entries)[name].value
        return value

    def to_dict(self) -> dict[str, Any]:
        """For a report: what the filter was told, with the sources."""
        return {
            "prior": {
                name: {"mean": p.mean, "sd": p.sd, "source": p.source} for name, p in self.prior
            },
            "random_walk": {n: t.value for n, t in self.random_walk},
            "model_error": {n: t.value for n, t in self.model_error},
            **(
                {MODEL_ERROR_AUGMENTED: {n: t.value for n, t in self.model_error_augmented}}
                if self.model_error_augmented
                else {}
            ),
            **(
                {MODEL_ERROR_MAP_SCALE: {n: t.value for n, t in self.model_error_map_scale}}
                if self.model_error_map_scale
                else {}
            ),
            **(
                {
                    "in_gear_by_shift": [
                        {"table": kind, "shift": shift, **{n: t.value for n, t in entries}}
                        for kind, shift, entries in self.in_gear_by_shift
                    ]
                }
                if self.in_gear_by_shift
                else {}
            ),
            "tuned_on": self.tuned_on,
            "mu_model": self.mu_model,
        }


def _unit_of(name: str) -> str:
    return _PRIOR_UNITS.get(name) or record(name).unit


def parse_estimator_table(
    table: Any, shafts: Sequence[str] = (), gears: Sequence[str] = ()
) -> EstimatorCalibration:
    """The ``[estimator]`` table read through a
    :class:`~gearsym.symbolic.io.table_reader.TableReader` (an absent table: every default).
    One-line errors name the file and the key; ``shafts``: the description's shafts, whose
    speeds ``omega_<shaft>`` may carry a model-error intensity; ``gears``: the description's
    gears, between which a model-error table's ``shift."<from>-<to>"`` sub-tables are."""
    shaft_states = {f"omega_{name}" for name in shafts}
    tuned_on = table.string("tuned_on", required=False, default="")
    mu_model = table.string("mu_model", required=False, default="random_walk")
    if mu_model not in MU_MODELS:
        raise table.fail("mu_model", f"expected one of {', '.join(MU_MODELS)}, got {mu_model!r}")
    priors: list[tuple[str, Prior]] = []
    prior_table = table.table("prior", required=False)
    for name in list(prior_table.data):
        if name not in PRIOR_NAMES:
            raise prior_table.fail(name, f"unknown prior (known: {', '.join(sorted(PRIOR_NAMES))})")
        entry = prior_table.table(name)
        mean = entry.number("mean", required=False)
        sd = entry.number("sd")
        assert sd is not None
        unit = entry.string("unit")
        source = entry.string("source")
        entry.reject_unknown()
        if unit != _unit_of(name):
            raise entry.fail("unit", f"expected {_unit_of(name)!r}, got {unit!r}")
        if not sd > 0:
            raise entry.fail("sd", f"must be positive, got {sd:g}")
        if not source.strip():
            raise entry.fail("source", "must say where the value comes from (or 'assumed')")
        if mean is not None and name == "m_veh" and mean <= 0:
            raise entry.fail("mean", f"must be positive, got {mean:g}")
        priors.append((name, Prior(sd=sd, mean=mean, source=source)))
    prior_table.reject_unknown()
    tables = {}
    by_shift: list[tuple[str, str, tuple[tuple[str, Tuning], ...]]] = []
    for kind in ("random_walk", "model_error", MODEL_ERROR_AUGMENTED, MODEL_ERROR_MAP_SCALE):
        sub = table.table(kind, required=False)
        values: list[tuple[str, Tuning]] = []
        for name in list(sub.data):
            if kind != "random_walk" and name == SHIFT_KEY:
                by_shift += [(kind, *own) for own in _in_gear_shifts(sub.table(name), gears)]
                continue
            if kind == "random_walk" and name not in RANDOM_WALK_NAMES:
                raise sub.fail(
                    name,
                    f"not a random-walk parameter (known: {', '.join(RANDOM_WALK_NAMES)})",
                )
            if kind != "random_walk" and not (
                name in MODEL_ERROR_NAMES or name in shaft_states or name in IN_GEAR_ENTRIES
            ):
                known = ", ".join((*MODEL_ERROR_NAMES, *sorted(shaft_states), *IN_GEAR_ENTRIES))
                raise sub.fail(name, f"not a state of a filter's model (known: {known})")
            values.append((name, _tuning(sub.table(name), name)))
        sub.reject_unknown()
        tables[kind] = tuple(values)
    table.reject_unknown()
    return EstimatorCalibration(
        prior=tuple(priors),
        random_walk=tables["random_walk"],
        model_error=tables["model_error"],
        model_error_augmented=tables[MODEL_ERROR_AUGMENTED],
        model_error_map_scale=tables[MODEL_ERROR_MAP_SCALE],
        in_gear_by_shift=tuple(by_shift),
        tuned_on=tuned_on,
        mu_model=mu_model,
        file=table.file,
    )


def _tuning(entry: Any, name: str) -> Tuning:
    """One ``{ value, unit, source }`` entry of a random-walk or model-error table."""
    value = entry.number("value")
    assert value is not None
    unit = entry.string("unit")
    source = entry.string("source")
    entry.reject_unknown()
    if not (math.isfinite(value) and value >= 0):
        raise entry.fail("value", f"must be finite and >= 0, got {value:g}")
    if name == IN_GEAR and unit != "1":
        raise entry.fail("unit", f"a factor: expected '1', got {unit!r}")
    if name == IN_GEAR_SETTLE and unit != "s":
        raise entry.fail("unit", f"a time: expected 's', got {unit!r}")
    if not source.strip():
        raise entry.fail("source", "must say where the value comes from (or 'assumed')")
    return Tuning(value, unit, source)


def _in_gear_shifts(
    shifts: Any, gears: Sequence[str]
) -> list[tuple[str, tuple[tuple[str, Tuning], ...]]]:
    """A model-error table's ``shift`` sub-tables: per shift ``"<from>-<to>"`` between two of
    the description's ``gears``, its :data:`IN_GEAR_ENTRIES` (the in-gear factor and settling
    time of that shift's filter, calibrated per shift type)."""
    found = []
    for shift in list(shifts.data):
        ends = shift.split("-")
        if (
            len(ends) != 2
            or (gears and not all(end in gears for end in ends))
            or ends[0] == ends[1]
        ):
            raise shifts.fail(
                shift, f"not a shift between two of the description's gears ({', '.join(gears)})"
            )
        own = shifts.table(shift)
        entries = []
        for name in list(own.data):
            if name not in IN_GEAR_ENTRIES:
                raise own.fail(name, "a shift may state in_gear and in_gear_settle only")
            entries.append((name, _tuning(own.table(name), name)))
        own.reject_unknown()
        found.append((shift, tuple(entries)))
    shifts.reject_unknown()
    return found
