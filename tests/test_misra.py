"""MISRA C:2012 through cppcheck's add-on: every rule the emitted C breaks is a documented
deviation (validation/checks/misra.py), and the table of the docs page docs/misra.md lists exactly
those rules.

The files checked cover every template path: the full model, a torque-input and a μ-form
shift model, a sensitivity system, the EKF, the extended UIO, the UIO, the friction element,
the μ map and the example; the other shift models come from the same templates. In CI a
missing cppcheck fails the test.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from gearsym.validation.checks.misra import DEVIATIONS, MisraUnavailable, misra_rules

ROOT = Path(__file__).resolve().parents[1]
FILES = [
    "gearsym_full.c",
    "gearsym_shift_2_3.c",
    "gearsym_shift_2_3_mu.c",
    "gearsym_shift_2_3_mu_sens.c",
    "gearsym_ekf_2_3.c",
    "gearsym_euio_2_3.c",
    "gearsym_uio_2_3.c",
    "gearsym_shift_element.c",
    "gearsym_mu_map.c",
    "main.c",
]


@pytest.mark.slow
def test_every_misra_finding_is_a_documented_deviation():
    try:
        counts = misra_rules([ROOT / "generated" / "c" / name for name in FILES])
    except MisraUnavailable as err:
        if os.environ.get("CI"):
            raise
        pytest.skip(str(err))
    assert counts, "cppcheck's MISRA add-on reported nothing: is it working?"
    undocumented = sorted(set(counts) - set(DEVIATIONS))
    assert not undocumented, f"rules broken without a documented deviation: {undocumented}"


def test_the_docs_list_exactly_the_deviations():
    text = (ROOT / "docs" / "misra.md").read_text(encoding="utf-8")
    section = text.split("# MISRA C:2012", 1)[1].split("\n# ", 1)[0]
    listed = set(re.findall(r"^\| (\d+\.\d+) \|", section, flags=re.M))
    assert listed == set(DEVIATIONS)
