"""Shared fixtures. `shared_data` is ../shared/data beside the checkout (CI puts it there)."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as station.cli does: small solves, 2 cores
os.environ.setdefault("STATION_CATALOG", "off")  # no catalog under the working folder; tests/catalog turn it on

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = (REPO / ".." / "shared").resolve()


def require_shared_data() -> Path:
    """../shared/data beside the checkout. Without it: a skip naming why (a clone on its own runs
    everything else), but a failure under CI=true, where it must be there."""
    path = SHARED / "data"
    if not path.is_dir():
        why = f"shared data not found at {path}: clone the repo next to shared/ (as CI does)"
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(why)
    return path


@pytest.fixture(scope="session")
def shared_data() -> Path:
    return require_shared_data()


