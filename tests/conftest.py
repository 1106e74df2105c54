"""Suite-wide settings and shared fixtures.

The output cache of the inspection commands is off, so that every test sees a fresh derivation
(tests/test_command_cache.py turns it on in its own subprocesses). Tests marked ``slow`` are left
out of the fast tier (`make test`); `make check` runs everything."""

from __future__ import annotations

import os
from typing import Any

import pytest

os.environ["GEARSYM_NO_CACHE"] = "1"
os.environ.pop("GEARSYM_CACHE_DIR", None)


@pytest.fixture(scope="session")
def generated_tree() -> Any:
    """The built-in gearbox's generated tree, derived once per test run (per xdist worker):
    every test that needs the default tree in memory shares it instead of deriving its own."""
    from gearsym.symbolic.export.generate import generate_tree
    from gearsym.symbolic.loader import load_description

    return generate_tree(load_description(None))


@pytest.fixture(scope="session")
def default_description() -> Any:
    """The built-in gearbox's description (the calibration of the fleet studies), loaded once."""
    from gearsym.symbolic.loader import load_description

    return load_description(None)


@pytest.fixture(scope="session")
def default_scenario(default_description: Any) -> Any:
    """The built-in power-on 2-3 scenario on the built-in gearbox, loaded once."""
    from gearsym.validation.sim.scenario import load_scenario

    return load_scenario(default_description, None)
