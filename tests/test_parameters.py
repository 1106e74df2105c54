"""One record per parameter (symbolic/parameters.py): every stage reads unit, description,
range, sign, plot symbol, random walk and prior from it, and nothing defines them again."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from gearsym.symbolic import naming, parameters
from gearsym.symbolic.description import SECTION_UNITS, SIGNED_QUANTITIES
from gearsym.symbolic.drivetrain import full_model
from gearsym.symbolic.estimator_calibration import EstimatorCalibration
from gearsym.symbolic.estimators.ekf import RANDOM_WALK
from gearsym.symbolic.export.generate import MU_BOUNDS, PARAMETER_BOUNDS
from gearsym.symbolic.loader import load_description

ROOT = Path(__file__).resolve().parents[1]


def test_every_model_parameter_has_a_record_that_agrees_with_the_model() -> None:
    """The full model's parameters (2.53) of the built-in box: unit, description and sign as
    the record states, and the built-in default inside the record's range."""
    model = full_model(load_description(None))
    for v in model.parameters:
        r = parameters.record(v.name)
        assert v.unit == r.unit, v.name
        if not parameters.is_mu(v.name):
            assert v.description == r.description, v.name
        lo, hi = r.bounds
        assert (lo is None or v.default >= lo) and (hi is None or v.default <= hi), v.name
        assert v.symbol.is_positive is (None if r.signed else True), v.name


def test_the_stages_read_the_records() -> None:
    """Each stage's table equals the records' (a value typed again elsewhere would differ)."""
    for section, units in SECTION_UNITS.items():
        for key, unit in units.items():
            assert parameters.record(key).section == section and parameters.record(key).unit == unit
    assert SIGNED_QUANTITIES == {
        r.key for r in parameters.RECORDS if r.signed and r.section != "element"
    }
    for key, bounds in PARAMETER_BOUNDS.items():
        assert parameters.record(key).bounds == bounds
    assert MU_BOUNDS == parameters.record("mu_05").bounds == (0.0, 1.0)
    for key, text in naming.DESCRIPTIONS.items():
        assert parameters.record(key).description == text
    assert RANDOM_WALK == {"m_veh": 1.0, "zeta": 2.5e-5, "mu": 4.0e-3}  # the stated defaults
    # a description without an [estimator] table: the records' default priors around its values
    empty = EstimatorCalibration()
    assert empty.prior_of("m_veh", 1800.0) == (1800.0, 0.3 * 1800.0)  # relative σ
    assert empty.prior_of("zeta", 0.0) == (0.0, 0.05)
    assert empty.prior_of("mu_38", 0.12) == (0.12, 0.03)


@pytest.mark.parametrize(
    ("name", "symbol", "label"),
    [
        ("m_veh", "m_veh", "m_veh / kg"),
        ("zeta", "ζ", "ζ / rad"),
        ("mu_38", "μ₃₈", "μ₃₈"),
        ("mu_K2", "μ_K2", "μ_K2"),
        ("k_ss", "k_ss", "k_ss / N*m/rad"),
        ("unknown", "unknown", "unknown"),
    ],
)
def test_plot_symbols_and_axis_labels(name: str, symbol: str, label: str) -> None:
    assert parameters.symbol(name) == symbol
    assert parameters.axis_label(name) == label


def _numeric_tables_keyed_by_parameters(path: Path) -> list[str]:
    """Dict literals in ``path`` that map a recorded parameter name to a number."""
    keys = {r.key for r in parameters.RECORDS if r.random_walk or r.prior_sigma or r.bounds}
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Dict):
            continue
        for k, v in zip(node.keys, node.values, strict=True):
            numeric = isinstance(v, ast.Constant) and isinstance(v.value, int | float)
            numeric |= isinstance(v, ast.Tuple) and all(isinstance(e, ast.Constant) for e in v.elts)
            if isinstance(k, ast.Constant) and k.value in keys and numeric:
                found.append(f"{path.relative_to(ROOT)}:{k.lineno}: {k.value!r}")
    return found


def _line_of(relative: str, text: str) -> int:
    lines = (ROOT / relative).read_text(encoding="utf-8").splitlines()
    return next(i for i, line in enumerate(lines, 1) if text in line)


def test_no_module_types_a_parameters_numbers_again() -> None:
    """Ranges, random walks, priors and scales live in symbolic/parameters.py only (the EUIO's
    ROAD_FREE sets its model's road-load parameters to zero: values, not properties)."""
    allowed = {
        f"symbolic/estimators/euio.py:{n}: {k!r}"
        for n in [_line_of("symbolic/estimators/euio.py", "ROAD_FREE: dict")]
        for k in ("zeta", "f_roll", "c_W")
    }
    found = []
    for folder in ("symbolic", "validation", "gearsym"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path != ROOT / "symbolic" / "parameters.py":
                found += _numeric_tables_keyed_by_parameters(path)
    assert not set(found) - allowed, sorted(set(found) - allowed)
