"""``gearsym generate --check``'s comparison of the emitted EUIO step with the library
(validation/checks/euio_check.py): the emitted files pass, and a perturbed constant in them is
caught.

Expected values: the library's :func:`~gearsym.symbolic.estimators.euio.euio_step_full` along
the default 2-3 shift (the same run as tests/test_euio_c.py). The perturbations are small
changes of one number of the emitted text (the 1/24 of the E_d series in C and in CasADi, the
load column's r_dyn² in C): a check that passed them would not be checking the step.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from gearsym.symbolic.codegen import emit_all
from gearsym.symbolic.export.generate import euio_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks.euio_check import compare_euio, reference_steps
from gearsym.validation.checks.generated_check import comparison_ok

NAME = "euio_2_3"


@pytest.fixture(scope="module")
def emitted():
    d = load_description()
    m = euio_model(d, shift_spec(d, "2-3"))
    files = emit_all(m.model, m.config)
    return files, reference_steps(d, m.model)


def _tree(root: Path, files: dict[str, str], replace: dict[str, tuple[str, str]]) -> Path:
    """The EUIO's files under root/c and root/python, with ``replace[file] = (old, new)``
    applied once (the old text must occur)."""
    for name, text in files.items():
        if name in replace:
            old, new = replace[name]
            assert old in text, (name, old)
            text = text.replace(old, new, 1)
        folder = root / ("python" if name.endswith(".py") else "c")
        folder.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text, encoding="utf-8")
    return root


def _by_target(reports):
    return {r.target.split(": ", 1)[1]: r for r in reports}


def test_the_emitted_step_passes(emitted, tmp_path):
    files, case = emitted
    reports = _by_target(compare_euio(NAME, case, _tree(tmp_path / "t", files, {}), tmp_path))
    for target, r in reports.items():
        print(target, {k: f"{v:.2g}" for k, v in r.max_error.items()})
        assert comparison_ok(r), r
    assert reports["C double"].worst() < 1e-12
    assert reports["CasADi"].worst() < 1e-12
    assert reports["C single"].worst() < 1e-5
    assert reports["C double"].n_points == len(case.steps) >= 100
    # the run covers dropouts (the status compared) and updates (the load compared)
    assert sum(not (st.y == st.y).all() for st in case.steps) >= 5


@pytest.mark.parametrize(
    ("file", "old", "new", "caught"),
    [
        # E_d's h^3 A^3 / 24 term in C: both C builds, not CasADi
        (
            f"gearsym_{NAME}.c",
            "GEARSYM_LIT(24.0)",
            "GEARSYM_LIT(24.5)",
            {"C double", "C single"},
        ),
        # the load column's r_dyn^2 (I_C^eff = I_wheel + m r_dyn^2) in C
        (f"gearsym_{NAME}.c", "GEARSYM_LIT(0.10804369)*x[4]", "GEARSYM_LIT(0.1081)*x[4]", None),
        # the same 1/24 in the CasADi module
        (
            f"gearsym_{NAME}_casadi.py",
            "ha @ (ha @ (ha @ e)) / 24",
            "ha @ (ha @ (ha @ e)) / 25",
            None,
        ),
    ],
)
def test_a_perturbed_constant_is_caught(emitted, tmp_path, file, old, new, caught):
    files, case = emitted
    root = _tree(tmp_path / "t", files, {file: (old, new)})
    target = "CasADi" if file.endswith(".py") else "C double"
    targets = (target, "C single") if target == "C double" else (target,)
    reports = _by_target(compare_euio(NAME, case, root, tmp_path, targets))
    failing = {t for t, r in reports.items() if not comparison_ok(r)}
    print(file, {t: f"{r.worst():.2g}" for t, r in reports.items()})
    assert failing == (caught if caught is not None else set(targets))


def test_the_checks_library_run_is_the_evaluations_reference_path():
    """reference_steps writes the EUIO loop out step by step for the check; without dropouts
    it must end where the evaluation's own loop (euio_filter_run, the reference's modes) ends
    on the same seed, so a change to one loop cannot leave the check on another filter."""
    import numpy as np
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.euio_evaluation import euio_filter_run, prepare_euio

    d = load_description()
    result = simulate(d, load_scenario(d, None))
    last = reference_steps(d, seed=5, dropout_every=0, result=result).steps[-1].result
    trial = euio_filter_run(prepare_euio(d, result, modes="reference"), 5)
    sigma = np.sqrt(np.diag(last.P))
    assert np.max(np.abs(trial.run.estimates[-1] - last.z) / (np.abs(last.z) + sigma)) < 1e-8
    assert np.max(np.abs(trial.run.sigmas[-1] - sigma) / sigma) < 1e-8
