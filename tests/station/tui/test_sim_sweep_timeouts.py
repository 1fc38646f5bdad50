"""Sweeps from the terminal UI on the simulated rig at the UI's default time scale (0.02) record no
fault the rig did not have, and still record the faults it has (issue 17).

At time scale 0.02 one real millisecond is 50 ms of the rig's clock. The UI runs the sweep in a
worker thread of the process that also draws the screens, so the sweep's thread is often kept
waiting for tens of milliseconds; the move timeout once counted that wait as motion time and
recorded `timeout` faults (`the drive did not reach ...`) the CLI never saw. The sweeps here run
through the app's own sweep job (StationApp.start_sweep -> station.services.sweep_job, on the rig
the app opened with station.services.wiring.open_rig) with the Sweep page drawing, and a thread of pure
Python work competing for the interpreter, as a busy redraw does.
"""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path

import pytest

from procedures.acquisition.plans import iso230_plan
from procedures.io.recording.reader import read_session
from procedures.io.recording.schema import FLAG_RETRIED_DRIVE
from station.commands.ui import DEFAULT_SIM_TIME_SCALE
from station.services.sweep_job import SweepRequest
from station.tui.app import StationApp

pytestmark = pytest.mark.timeout(300)

SWEEPS = 50
# one leg, five targets over 40 mm, one cycle: 10 points, about a second per sweep
PLAN = iso230_plan((1,), -20.0, 20.0, n_targets=5, cycles=1, dwell_s=0.2)


class Hog:
    """A thread doing pure Python work (it holds the interpreter lock for its switch interval at
    a time, as the UI does while it lays out and draws a page)."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gil-hog", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            x = 0
            for i in range(100_000):
                x += i

    def __enter__(self) -> "Hog":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5.0)


async def _open_sweep_page(pilot, connected, wait_until) -> None:
    app = pilot.app
    await connected(pilot)
    assert app.rig.kind == "sim" and app.rig.clock.time_scale == DEFAULT_SIM_TIME_SCALE
    await pilot.press("f2")
    await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")


async def _sweep(pilot, wait_until, out: Path, during=None) -> str:
    """Run PLAN through the app's sweep job to `out`; `during(app)` is polled while it runs.
    Returns the outcome the app saw once the sweep job had ended."""
    app = pilot.app
    ended: list[str] = []
    assert app.start_sweep(SweepRequest(out=out, plan=PLAN, make_parents=True), on_done=lambda state: ended.append(state.status)), \
        "the app refused the sweep"
    while not ended:
        if during is not None:
            during(app)
        await pilot.pause(0.01)
    return ended[0]


@pytest.mark.slow  # about 70 s on two cores
def test_fifty_ui_sweeps_at_the_default_time_scale_record_no_fault(cfg, size, connected, wait_until):
    asyncio.run(_fifty_sweeps(cfg, size, connected, wait_until))


async def _fifty_sweeps(cfg, size, connected, wait_until):
    app = StationApp(cfg, time_scale=DEFAULT_SIM_TIME_SCALE)
    folder = Path(cfg.recordings_dir)
    outcomes = []
    t0 = time.monotonic()
    async with app.run_test(size=size) as pilot:
        await _open_sweep_page(pilot, connected, wait_until)
        with Hog():
            for k in range(SWEEPS):
                outcomes.append(await _sweep(pilot, wait_until, folder / f"sweep-{k:02d}.h5"))
        await pilot.press("ctrl+q")
    took = time.monotonic() - t0
    faulty, incomplete = {}, {}
    for k in range(SWEEPS):
        s = read_session(folder / f"sweep-{k:02d}.h5")
        if len(s.faults):
            faulty[k] = [(f["kind"].decode(), f["message"].decode()) for f in s.faults]
        if s.outcome != "completed" or len(s.points) != PLAN.total_points:
            incomplete[k] = (s.outcome, len(s.points), outcomes[k])
    assert not faulty, f"{len(faulty)} of {SWEEPS} sweeps recorded a fault the rig did not have: {faulty}"
    assert not incomplete, f"sweeps that did not complete (outcome, points, as the UI saw it): {incomplete}"
    assert outcomes == ["completed"] * SWEEPS
    print(f"{SWEEPS} UI sweeps at time scale {DEFAULT_SIM_TIME_SCALE:g}, no fault, in {took:.1f} s")


@pytest.mark.parametrize("injected", ["stall", "drive_fault"])
def test_an_injected_fault_is_still_recorded_at_the_default_time_scale(cfg, size, connected, wait_until, injected):
    asyncio.run(_injected(cfg, size, connected, wait_until, injected))


async def _injected(cfg, size, connected, wait_until, injected):
    app = StationApp(cfg, time_scale=DEFAULT_SIM_TIME_SCALE)
    out = Path(cfg.recordings_dir) / f"{injected}.h5"
    armed = []

    def inject(app) -> None:
        if armed or app.sweep.done < 2:
            return
        armed.append(app.sweep.done)
        if injected == "stall":  # the axis jams: every move from now on never arrives
            app.rig.sim.drive_server.set_stalled(1)
        else:  # the drive latches a fault once; the sweep resets it and goes on
            app.rig.sim.drive_server.inject_fault(1, "overcurrent")

    async with app.run_test(size=size) as pilot:
        await _open_sweep_page(pilot, connected, wait_until)
        with Hog():
            outcome = await _sweep(pilot, wait_until, out, during=inject)
        if injected == "stall":
            app.rig.sim.drive_server.set_stalled(1, False)
        await pilot.press("ctrl+q")
    assert armed and armed[0] < PLAN.total_points, "the fault was injected while the sweep ran"
    s = read_session(out)
    kinds = [f["kind"].decode() for f in s.faults]
    if injected == "stall":
        # a real non-arrival: timed out on every attempt, given up, the session failed there
        assert outcome == "failed" and s.outcome == "failed"
        assert kinds == ["timeout"] * len(kinds) and len(kinds) == 3, kinds
        assert [int(f["attempt"]) for f in s.faults] == [1, 2, 3]
        assert [bool(f["gave_up"]) for f in s.faults] == [False, False, True]
        assert all(b"the drive did not reach" in f["message"] for f in s.faults)
        assert len(s.points) < PLAN.total_points
    else:
        # recorded, retried, and the sweep completed with the point flagged
        assert outcome == "completed" and s.outcome == "completed"
        assert kinds == ["drive_fault"] and not s.faults[0]["gave_up"]
        assert b"overcurrent" in s.faults[0]["message"].lower()
        assert len(s.points) == PLAN.total_points
        flagged = s.points[(s.points["flags"] & FLAG_RETRIED_DRIVE) != 0]
        assert list(flagged["index"]) == [int(s.faults[0]["index"])]
