"""Helpers for the TUI tests: a station config writing into tmp_path, and a bounded wait."""

from __future__ import annotations

import time

import pytest

from station.config import StationConfig

SIZE = (120, 40)


@pytest.fixture
def cfg(tmp_path) -> StationConfig:
    c = StationConfig(operator="test")
    c.recordings_dir = str(tmp_path / "runs")
    return c


async def _wait_until(pilot, condition, timeout_s: float = 20.0, what: str = "condition") -> None:
    """Let the app process messages until `condition()` holds; fail after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")
        await pilot.pause(0.01)


async def _connected(pilot, timeout_s: float = 20.0) -> None:
    app = pilot.app
    await _wait_until(pilot, lambda: app.rig_state != "connecting", timeout_s, "the rig connection")
    assert app.rig is not None, f"rig did not connect: {app.rig_error}"


@pytest.fixture
def wait_until():
    """`await wait_until(pilot, condition, timeout_s, what)`: bounded wait for a condition."""
    return _wait_until


@pytest.fixture
def connected():
    """`await connected(pilot)`: wait for the app's rig connection and require success."""
    return _connected


@pytest.fixture
def size():
    return SIZE


@pytest.fixture(scope="module")
def recorded_session(tmp_path_factory):
    """A small completed session from the simulated rig (legs 1 and 2, 9 uniform targets
    -80..80 mm, 3 cycles), recorded by the same runner as the CLI and the UI."""
    from procedures.plans import iso230_plan
    from station.jobs import run_sweep
    from station.wiring import open_rig

    out = tmp_path_factory.mktemp("session") / "two-legs.h5"
    plan = iso230_plan((1, 2), -80.0, 80.0, step_mm=20.0, cycles=3)
    cfg = StationConfig(operator="test")
    with open_rig(cfg, legs=(1, 2), time_scale=0.0) as rig:
        result = run_sweep(rig, plan, out, cfg)
    assert result.outcome == "completed"
    return out


def notifications(app) -> list[str]:
    return [n.message for n in app._notifications]


@pytest.fixture
def notes():
    """`notes(app)`: the texts of the notifications the app is showing."""
    return notifications
