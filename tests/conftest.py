"""Shared fixtures. `shared_data` is ../shared/data beside the checkout (CI puts it there)."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as station.cli does: small solves, 2 cores

import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = (REPO / ".." / "shared").resolve()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    path = SHARED / "data"
    if not path.is_dir():
        pytest.fail(f"shared data not found at {path}: clone the repo next to shared/ (as CI does)")
    return path


def require_tool(name: str) -> str:
    """Path of a Debian tool; skip when absent, except on CI (CI=true) where it must exist."""
    path = shutil.which(name)
    if path:
        return path
    if os.environ.get("CI") == "true":
        pytest.fail(f"{name} is required on CI (.ci/run installs it)")
    pytest.skip(f"{name} not installed (apt-get install it to run this test)")
