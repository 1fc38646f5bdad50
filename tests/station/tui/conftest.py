"""Helpers for the TUI tests: a station config writing into tmp_path, and a bounded wait."""

from __future__ import annotations

import time

import pytest

from station.services.config import StationConfig

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


async def _rig_keys_act(pilot, since: float, timeout_s: float = 20.0) -> None:
    """Wait until a rig key (StationScreen.RIG_KEYS) pressed now acts: the page has seen what
    happened at `since` (time.monotonic(); a text field losing the focus, keys typed outside a
    field: its hold is stamped when the page handles it, which on a busy machine comes later)
    and STRAY_HOLD_S has passed since. A fixed pause of STRAY_HOLD_S after the focus change is
    not enough: the hold starts when the blur is handled, not when the focus was moved."""
    screen = pilot.app.screen
    await _wait_until(pilot, lambda: screen._stray_at >= since, timeout_s, "the page to see the field left")
    await _wait_until(pilot, lambda: time.monotonic() - screen._stray_at > screen.STRAY_HOLD_S, timeout_s,
                      "the page's hold on the rig keys to end")


@pytest.fixture
def rig_keys_act():
    """`await rig_keys_act(pilot, since)`: wait until the page's rig keys act again after a text
    field lost the focus (or keys were typed outside one) at `since` (time.monotonic())."""
    return _rig_keys_act


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
    from procedures.acquisition.plans import iso230_plan
    from station.services.jobs import run_sweep
    from station.services.wiring import open_rig

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


def write_six_leg_session(path, legs=(1, 2, 3, 4, 5, 6), cycles: int = 3, step_mm: float = 3.0, seed: int = 0):
    """A small synthetic session straight from the simulated plant (procedures.synthetic, no protocol
    layer): `legs` of the default leg configs, uniform targets -90..90 mm, `cycles` cycles."""
    from tests.tooling import default_legs_points, write_points_session

    return write_points_session(path, default_legs_points(legs, cycles, step_mm, seed))


@pytest.fixture
def six_leg_session(tmp_path):
    """A synthetic six-leg session (3 cycles, 61 targets) in its own folder under tmp_path."""
    folder = tmp_path / "sessions"
    folder.mkdir()
    return write_six_leg_session(folder / "six-legs.h5")


@pytest.fixture
def synth_session_file():
    """`synth_session_file(path, legs=..., cycles=..., step_mm=...)`: write a synthetic session."""
    return write_six_leg_session
