"""Suite-wide settings: the output cache of the inspection commands is off, so that every test
sees a fresh derivation (tests/test_command_cache.py turns it on in its own subprocesses)."""

from __future__ import annotations

import os

os.environ["GEARSYM_NO_CACHE"] = "1"
os.environ.pop("GEARSYM_CACHE_DIR", None)
