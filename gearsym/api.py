"""The notebook API: one object per gearbox, thin calls into the library.

>>> import gearsym
>>> box = gearsym.load()                      # the built-in thesis gearbox (or a TOML path)
>>> box.ratios()["2"]                         # Table 2.1
3.2432...
>>> model = box.shift_model("2-3")            # (2.55)-(2.58), the IR every analysis consumes
>>> result = box.simulate()                   # reference simulation (thesis 3.1)
>>> study = box.fim(result=result)            # Fisher information per phase (3.25)
>>> box.observability("2-3").result.rank      # (4.12): rank 8, proved by a witness minor
8
>>> box.estimate("ekf").data["nees_mean"]     # the EKF (4.3) on the 2-3 shift  # doctest: +SKIP
>>> tree = box.generate()                     # emitted C and CasADi, in memory
>>> box.generate("out/code")                  # written through the one output writer

Everything here is what the command line does, without printing: the CLI modules parse and
print, this module calls, the library computes. Heavy modules are imported on first use, so
``import gearsym`` stays light.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["Gearbox", "load"]


def load(path: str | Path | None = None) -> Gearbox:
    """The gearbox described by the TOML file ``path`` (default: the built-in one). Bad input
    raises :class:`gearsym.symbolic.errors.GearsymError` (one line: file, key, reason)."""
    from gearsym.symbolic.loader import load_description

    return Gearbox(load_description(None if path is None else str(path)))


@dataclass(frozen=True)
class Gearbox:
    """A checked gearbox description and the analyses of it."""

    description: Any  # gearsym.symbolic.description.GearboxDescription

    @property
    def name(self) -> str:
        return str(self.description.name)

    def ratios(self) -> dict[str, float | None]:
        """ω_in/ω_out of every gear (None for a neutral), derived from the teeth (Table 2.1)."""
        from gearsym.symbolic.ratios import ratio_table

        return {
            r.gear: (None if r.ratio is None else float(r.ratio))
            for r in ratio_table(self.description)
        }

    def full_model(self, with_wheel_acceleration: bool = False) -> Any:
        """The full model (2.53): every element torque an input."""
        from gearsym.symbolic.drivetrain import full_model

        return full_model(self.description, with_wheel_acceleration=with_wheel_acceleration)

    def shift_model(
        self, shift: str, friction_inputs: bool = False, with_wheel_acceleration: bool = False
    ) -> Any:
        """The reduced model of a shift (2.55)-(2.58), e.g. ``"2-3"``; with
        ``friction_inputs`` the element torques are μ·F_N (3.14) with F_N as inputs."""
        from gearsym.symbolic.drivetrain import shift_model

        return shift_model(
            self.description,
            shift,
            with_wheel_acceleration=with_wheel_acceleration,
            friction_inputs=friction_inputs,
        )

    def scenario(self, path: str | Path | None = None) -> Any:
        """A shift scenario (default: the built-in 2-3 power-on upshift)."""
        from gearsym.validation.sim.scenario import load_scenario

        return load_scenario(self.description, path)

    def measurement(self, recording: str | Path, scenario: Any) -> Any:
        """A bench recording (MDF4 or CSV) read with the ``[measurement]`` channel map of
        ``scenario`` (a path, a loaded scenario, or None: the built-in one, which has no map),
        in SI units on the analysis grid
        (:func:`gearsym.validation.sim.measurement.read_measurement`)."""
        from gearsym.symbolic.errors import GearsymError
        from gearsym.validation.sim.measurement import read_measurement

        if scenario is None or isinstance(scenario, str | Path):
            scenario = self.scenario(scenario)
        if scenario.measurement is None:
            raise GearsymError(
                scenario.file, "measurement", "missing table [measurement] (the channel map)"
            )
        return read_measurement(recording, scenario.measurement, scenario.t_end)

    def simulate(self, scenario: Any = None, measurement: Any = None, **options: Any) -> Any:
        """Reference simulation (thesis 3.1): ``scenario`` a path or a loaded scenario;
        ``measurement`` a recording (path, or from :meth:`measurement`) whose inputs drive
        it; ``options`` go to :func:`gearsym.validation.sim.simulate.simulate` (``method``,
        ``rtol``, ``sample_time``, ``check_models``, ``progress``)."""
        from gearsym.validation.sim.simulate import simulate

        if scenario is None or isinstance(scenario, str | Path):
            scenario = self.scenario(scenario)
        if measurement is not None:
            from gearsym.validation.sim.scenario import with_measured_inputs

            if isinstance(measurement, str | Path):
                measurement = self.measurement(measurement, scenario)
            scenario = with_measured_inputs(scenario, measurement)
        return simulate(self.description, scenario, **options)

    def sensitivities(
        self, parameters: list[str] | None = None, result: Any = None, **options: Any
    ) -> Any:
        """Sensitivities (3.5)-(3.7) along the reference shift (``result`` reuses a
        simulation; default parameters: the thesis' set (3.2) for the shift)."""
        from gearsym.validation.studies.driven_shift import reference_from_result
        from gearsym.validation.studies.sensitivity_run import run_sensitivities

        data = reference_from_result(result) if result is not None else None
        return run_sensitivities(self.description, parameters, data=data, **options)

    def fim(self, parameters: list[str] | None = None, result: Any = None, **options: Any) -> Any:
        """Fisher information (3.25) per phase; by default each phase counts only what it
        reveals itself (``restart=False``: the thesis' continuous view, labelled)."""
        from gearsym.validation.studies.driven_shift import reference_from_result
        from gearsym.validation.studies.fisher import fim_study

        data = reference_from_result(result) if result is not None else None
        return fim_study(self.description, parameters, data=data, **options)

    def observability(self, shift: str = "2-3", **options: Any) -> Any:
        """Observability of the augmented shift model (4.1)-(4.12): generic rank of Q with its
        witness, and where the rank drops (``options`` as ``gearsym observability``: params,
        input_models, conditions, max_order, drop_search, seed, ...)."""
        from gearsym.symbolic.observability import analyze_shift

        return analyze_shift(self.description, shift, **options)

    def estimate(
        self,
        filter: str = "ekf",
        scenario: Any = None,
        *,
        out: str | Path | None = None,
        **options: Any,
    ) -> Any:
        """Run an estimator of thesis chapter 4 (``"uio"``, ``"ekf"``, ``"euio"``) on the
        reference shift of ``scenario`` (a path, a loaded scenario, or None: the built-in
        2-3) and return its report (``.data`` as ``gearsym estimate --json``, ``.text``,
        ``.result``). ``options``: the calibration's (``sample_time``, ``relative_noise``,
        ``parameters``, ``initial``, ``modes``) and the evaluation's (``runs``, ``seed``,
        ``initial_from_prior``, ``dropout``, ``dropout_outputs``, ``unknown``) fields of
        :class:`~gearsym.validation.studies.estimation.workflow.Calibration` and
        :class:`~gearsym.validation.studies.estimation.workflow.EstimateRequest`. With
        ``out``, the CSV, JSON and plots are written there through the one output writer."""
        from dataclasses import fields

        from gearsym.symbolic.errors import GearsymError
        from gearsym.symbolic.io.output_dir import OutputDir
        from gearsym.validation.studies.estimation.workflow import (
            Calibration,
            EstimateRequest,
            Truth,
            estimate,
        )

        source = "built-in" if scenario is None else str(getattr(scenario, "file", scenario))
        if scenario is None or isinstance(scenario, str | Path):
            scenario = self.scenario(scenario)
        known_cal = {f.name for f in fields(Calibration)} - {"description"}
        known_req = {f.name for f in fields(EstimateRequest)} - {
            "filter",
            "calibration",
            "truths",
        }
        unknown = sorted(set(options) - known_cal - known_req)
        if unknown:
            raise GearsymError("estimate", unknown[0], "is not an option of the estimate")
        tuples = ("relative_noise", "parameters", "dropout_outputs", "unknown")
        options = {k: tuple(v) if k in tuples and v is not None else v for k, v in options.items()}
        calibration = Calibration(
            self.description, **{k: v for k, v in options.items() if k in known_cal}
        )
        request = EstimateRequest(
            filter=filter,
            calibration=calibration,
            truths=(Truth(scenario, source),),
            **{k: v for k, v in options.items() if k in known_req},
        )
        if out is None:
            return estimate(request)
        with OutputDir(out, "estimate") as staged:
            report = estimate(request, staged.path)
            staged.commit()
        return report

    def generate(self, out: str | Path | None = None) -> Any:
        """The emitted C and CasADi tree (``GeneratedTree``: files by relative path, models).
        With ``out``, also written there through the one output writer (atomic; never over a
        folder gearsym did not write)."""
        from gearsym.symbolic.export.generate import generate_tree
        from gearsym.symbolic.io.output_dir import OutputDir

        tree = generate_tree(self.description)
        if out is not None:
            with OutputDir(out, "generate") as staged:
                for relative, text in sorted(tree.files.items()):
                    path = staged.path / relative
                    path.parent.mkdir(parents=True, exist_ok=True)
                    path.write_text(text, encoding="utf-8", newline="\n")
                staged.commit()
        return tree
