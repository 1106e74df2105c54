"""What a ``gearsym estimate`` request is made of, apart from what runs it: what the filter
knows (:class:`Calibration`), the world it is judged in (:class:`Truth`), the request itself
(:class:`EstimateRequest`), where the workflow reports progress (:class:`Reporter`) and what it
returns (:class:`EstimateReport`); shared by the workflow (:mod:`.workflow`) and the fleet's
(:mod:`.fleet_workflow`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.sim.scenario import Scenario

__all__ = [
    "DEFAULT_RELATIVE_NOISE",
    "DEFAULT_SAMPLE_TIME",
    "DEFAULT_WORKERS",
    "DRIVE_UPSHIFTS",
    "FILTERS",
    "MAX_RELATIVE_NOISE",
    "MIN_SAMPLE_TIME",
    "Calibration",
    "EstimateReport",
    "EstimateRequest",
    "Reporter",
    "Silent",
    "Truth",
    "filter_noise",
    "refuse",
    "write_json",
]


FILTERS = ("uio", "ekf", "euio")

#: ``--drive upshifts``: the shipped scenarios of the drive 1->2->3->4.
DRIVE_UPSHIFTS = ("scenario_1_2.toml", "scenario_2_3.toml", "scenario_3_4.toml")

#: The filters' sensor-noise model when the calibration states none: the relative speed error
#: r (3.26) of the EKF and the EUIO; the UIO is run noise-free.
DEFAULT_RELATIVE_NOISE = 0.01

#: Largest relative speed-sensor error r (3.26) a request may state: σ equal to the speed
#: itself; beyond it the filter's covariances overflow (r = 1e300 ended in a LinAlgError).
MAX_RELATIVE_NOISE = 1.0

#: LocalCluster worker processes of ``--scheduler local`` when ``--workers`` is not given.
DEFAULT_WORKERS = 2

#: Default TCU sample time (s), the thesis'.
DEFAULT_SAMPLE_TIME = 0.01
#: The smallest sample time: the simulated record's spacing (0.5 ms); a smaller one would
#: only repeat samples, and 1e-9 s took the machine's memory.
MIN_SAMPLE_TIME = 0.0005


@dataclass(frozen=True)
class Calibration:
    """What the TCU knows; nothing here is read from the truth.

    ``relative_noise``: the filter's sensor-noise model, one relative error r (3.26) for every
    output or one per output (``None``: :data:`DEFAULT_RELATIVE_NOISE`; the UIO: no noise).
    ``parameters``: the EKF's augmented parameters (``None``: the thesis' (4.1)). ``initial``:
    initial estimates by state name. ``modes``: "filter" (the filter decides the element modes,
    as a TCU must) or "reference" (the reference simulation's, for comparison); ``None``:
    "filter". ``sample_time``: the TCU's (``None``: :data:`DEFAULT_SAMPLE_TIME`, or a
    recording's channel-map grid)."""

    description: GearboxDescription
    sample_time: float | None = None
    relative_noise: tuple[float, ...] | None = None
    parameters: tuple[str, ...] | None = None
    initial: Mapping[str, float] = field(default_factory=dict)
    modes: str | None = None
    #: overrides the description's ``[estimator] mu_model`` (``None``: the description's)
    mu_model: str | None = None
    #: :attr:`~gearsym.validation.studies.estimation.setup.EkfSetup.input_hold` (with a fleet)
    input_hold: str = "sample"

    @property
    def mode_source(self) -> str:
        return self.modes or "filter"

    @property
    def filter_sample_time(self) -> float:
        return DEFAULT_SAMPLE_TIME if self.sample_time is None else self.sample_time


@dataclass(frozen=True)
class Truth:
    """The world one evaluation runs in: ``scenario`` simulated by the reference, or its inputs
    and outputs taken from ``measurement`` (a bench recording, mapped by the scenario's
    ``[measurement]`` table). ``source`` names where the scenario came from, for the report."""

    scenario: Scenario
    source: str = "built-in"
    measurement: Any = None


@dataclass(frozen=True)
class EstimateRequest:
    """One ``gearsym estimate``: the filter, what it knows, the world(s), and the evaluation.

    ``truths``: one truth, or several consecutive shifts with ``drive`` (the EKF carries m_veh
    and ζ from one to the next). ``runs``/``seed``: Monte-Carlo over noise seeds seed, seed+1, …
    ``initial_from_prior``: each run's initial estimate drawn from the prior around the truth
    (the posterior bound's premise). ``dropout``: a sensor dropout (T0, T1) in s or the name of
    a detected phase ("speed phase"); ``dropout_outputs``: the outputs that drop out (default:
    all). ``unknown``: the UIO's unknown inputs (5.3). ``plots``: write the PNGs with files."""

    filter: str
    calibration: Calibration
    truths: tuple[Truth, ...]
    runs: int = 1
    seed: int = 0
    initial_from_prior: bool = False
    dropout: tuple[float, float] | str | None = None
    dropout_outputs: tuple[str, ...] | None = None
    unknown: tuple[str, ...] = ("T_res_star",)
    drive: bool = False
    plots: bool = True
    #: a :class:`~gearsym.validation.sim.fleet.Fleet`: each run draws its own vehicle (the
    #: truth) and the reference simulates it; ``None``: one truth equal to the calibration
    fleet: Any = None
    #: the command that made the request, for the Markdown table a fleet evaluation writes
    command: str = ""
    #: with ``fleet``: tune the model-error intensities on these runs' vehicles instead of
    #: evaluating (:func:`~gearsym.validation.studies.estimation.tuning.tune_model_error`)
    tune: bool = False
    #: with ``tune``: further shifts (scenarios) every tuning vehicle runs besides the truth's:
    #: one calibration's intensities for every shift it serves
    tune_scenarios: tuple[Any, ...] = ()
    #: with ``tune``: the factors tried on the model-error table's intensities of the speeds,
    #: of the twist and on its in-gear factor (``None``: the tuning's default axis; for the
    #: in-gear factor none, the table's own)
    tune_factors: tuple[float, ...] | None = None
    tune_twist_factors: tuple[float, ...] | None = None
    tune_in_gear: tuple[float, ...] | None = None
    #: with ``tune``: ``"pooled"`` or ``"per_shift"`` (:func:`~gearsym.validation.studies.
    #: estimation.tuning.tune_model_error`)
    tune_criterion: str = "pooled"
    #: with ``fleet``: run the vehicles on Dask, ``"local"`` (a LocalCluster of ``workers``
    #: processes, default :data:`DEFAULT_WORKERS`) or ``"tcp://HOST:PORT"`` (a running
    #: scheduler and its workers); ``None``: one after the other in this process
    scheduler: str | None = None
    workers: int | None = None

    @property
    def truth(self) -> Truth:
        return self.truths[0]


class Reporter(Protocol):
    """Where the workflow tells how far it is: ``say`` a step, ``bar`` a progress display
    (``bar(label)`` returns ``(update, done)``; ``update(fraction, message)``)."""

    def say(self, message: str) -> None: ...

    def bar(self, label: str) -> tuple[Callable[[float, str], None], Callable[[], None]]: ...


class Silent:
    """A reporter that says nothing (the library's default)."""

    def say(self, message: str) -> None:
        pass

    def bar(self, label: str) -> tuple[Callable[[float, str], None], Callable[[], None]]:
        return (lambda fraction, message: None), (lambda: None)


@dataclass
class EstimateReport:
    """What :func:`estimate` found: ``data`` (the JSON of ``gearsym estimate --json``),
    ``text`` (what it prints), ``result`` (the run or Monte-Carlo object, for a notebook)."""

    data: dict[str, Any]
    text: str
    result: Any = None

    def to_dict(self) -> dict[str, Any]:
        return self.data


def refuse(option: str, given: bool, reason: str) -> None:
    """A one-line :class:`GearsymError` naming ``option`` when ``given``."""
    if given:
        raise GearsymError("estimate", option, reason)


def filter_noise(cal: Calibration) -> Any:
    """The EKF's and the EUIO's noise model: one value for every output, or one per output."""
    if cal.relative_noise is None:
        return DEFAULT_RELATIVE_NOISE
    return list(cal.relative_noise)


def write_json(path: Path, data: Mapping[str, Any]) -> None:
    """``data`` as indented JSON at ``path`` (inside the one writer's staging folder)."""
    import json

    path.write_text(json.dumps(data, indent=2) + "\n")
