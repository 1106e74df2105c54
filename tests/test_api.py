"""The notebook API (gearsym.load): thin calls into the library, checked against the thesis."""

from __future__ import annotations

from pathlib import Path

import pytest
from gearsym.symbolic.errors import GearsymError

import gearsym

TABLE_2_1 = {"1": 5.354, "2": 3.243, "3": 2.252, "4": 1.636, "5": 1.211, "6": 1.0}
ROOT = Path(__file__).resolve().parents[1]


def test_load_and_ratios_reproduce_table_2_1() -> None:
    box = gearsym.load()
    assert box.name == "thesis_9speed"
    ratios = box.ratios()
    for gear, printed in TABLE_2_1.items():
        assert round(ratios[gear], 3) == printed


def test_shift_model_has_the_states_of_2_55() -> None:
    model = gearsym.load().shift_model("2-3", friction_inputs=True)
    assert [v.name for v in model.states] == ["omega_1", "omega_2", "phi", "omega_C"]
    assert {"mu_38", "mu_05"} <= {v.name for v in model.parameters}  # (3.14)


def test_bad_file_is_one_error(tmp_path: Path) -> None:
    with pytest.raises(GearsymError, match="no such file"):
        gearsym.load(tmp_path / "missing.toml")


def test_simulate_and_fim_through_the_api() -> None:
    box = gearsym.load()
    result = box.simulate(check_models=False)
    ratio = result.signals["ratio"]
    assert round(ratio[0], 3) == TABLE_2_1["2"] and round(ratio[-1], 3) == TABLE_2_1["3"]
    study = box.fim(["m_veh", "zeta"], result=result)
    assert [w.name for w in study.windows][:4] == [p.name for p in result.phases]


def test_generate_in_memory_and_to_a_folder(tmp_path: Path) -> None:
    box = gearsym.load()
    out = tmp_path / "code"
    tree = box.generate(out)
    written = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    assert written == set(tree.files)
    committed = ROOT / "generated"
    assert (out / "c" / "gearsym_full.c").read_text() == (
        committed / "c" / "gearsym_full.c"
    ).read_text()


def test_import_gearsym_stays_light() -> None:
    """`import gearsym` must not pull in the numeric stack (the CLI's start-up)."""
    import subprocess
    import sys

    heavy = "('sympy', 'numpy', 'scipy', 'casadi')"
    code = f"import sys, gearsym; print(sorted(m for m in {heavy} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_observability_through_the_api() -> None:
    """(4.12): generic rank 8 of Q_123 for the 2-3 shift, every state and parameter observable."""
    report = gearsym.load().observability("2-3", drop_search=False, seed=0)
    assert report.result.rank == report.result.n_unknowns == 8
    assert report.result.unobservable == () or not report.result.unobservable
