"""Helpers shared by test modules (import as `from tests.tooling import ...`; the repo root is on
sys.path via pytest's `pythonpath`, and a plain `conftest` import is ambiguous across folders)."""

from __future__ import annotations

import os
import shutil

import pytest


def require_tool(name: str) -> str:
    """Path of a Debian tool; skip when absent, except on CI (CI=true) where it must exist."""
    path = shutil.which(name)
    if path:
        return path
    if os.environ.get("CI") == "true":
        pytest.fail(f"{name} is required on CI (.ci/run installs it)")
    pytest.skip(f"{name} not installed (apt-get install it to run this test)")
