"""Rig screen and error handling on the simulated rig (real Modbus TCP + serial pty)."""

from __future__ import annotations

import asyncio
import socket

import pytest
from textual.widgets import DataTable, Input, Static

from procedures.io.recording.reader import read_session
from station.tui.app import StationApp

pytestmark = pytest.mark.timeout(120)


def cell(app, leg: int, col: int) -> str:
    table = app.screen.query_one("#drives", DataTable)
    return str(table.get_row_at(table.get_row_index(str(leg)))[col])


def test_rig_screen_shows_states_and_enable_home_fault_reset(cfg, size, connected, wait_until, notes):
    asyncio.run(_rig(cfg, size, connected, wait_until, notes))


async def _rig(cfg, size, connected, wait_until, notes):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.1)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await wait_until(pilot, lambda: "disabled" in cell(app, 1, 1) and "disabled" in cell(app, 6, 1),
                         what="the first status poll")
        assert "connected: " in str(app.screen.query_one("#rig-connection", Static).render())
        assert "beam ok" in str(app.screen.query_one("#laser", Static).render())
        assert "air " in str(app.screen.query_one("#environment", Static).render())
        # leg 1 is the selected row: enable it, then home it (mid-stroke reference, 0 mm)
        await pilot.press("e")
        await wait_until(pilot, lambda: "enabled" in cell(app, 1, 1), what="leg 1 enabled on screen")
        assert app.rig.axes[1].status().enabled and not app.rig.axes[2].status().enabled
        await pilot.press("h")
        await wait_until(pilot, lambda: any("home: leg 1 done" in n for n in notes(app)), what="home done")
        assert abs(app.rig.axes[1].status().position_mm) < 1e-3
        # a drive fault shows with the profile's text; enabling is refused until it is reset
        app.rig.sim.drive_server.inject_fault(1, "overcurrent")
        await wait_until(pilot, lambda: "FAULT" in cell(app, 1, 1), what="the fault on screen")
        assert "overcurrent" in cell(app, 1, 7)
        await pilot.press("e")
        await wait_until(pilot, lambda: any("in fault: reset the fault" in n for n in notes(app)), what="the refusal")
        await pilot.press("r")
        await wait_until(pilot, lambda: "FAULT" not in cell(app, 1, 1), what="the fault reset on screen")
        assert not app.rig.axes[1].status().fault
        # stop all leaves every drive still
        await pilot.press("x")
        await wait_until(pilot, lambda: any("stop: leg 1, 2, 3, 4, 5, 6 done" in n for n in notes(app)), what="stop all")
        assert not any(a.status().moving for a in app.rig.axes.values())


def test_unreachable_drives_are_a_notice_with_what_to_do(cfg, size, wait_until, notes):
    asyncio.run(_unreachable(cfg, size, wait_until, notes))


async def _unreachable(cfg, size, wait_until, notes):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg.drive.url = f"tcp://127.0.0.1:{port}"
    cfg.drive.timeout_s = 0.2
    cfg.interferometer.port = "/nonexistent/tty-for-test"
    app = StationApp(cfg)
    async with app.run_test(size=size) as pilot:
        await wait_until(pilot, lambda: app.rig_state == "not connected" and notes(app), 30, "the connection to fail")
        text = " ".join(notes(app))
        assert f"127.0.0.1:{port}" in text and "press c on the rig screen" in text.lower()
        assert "Traceback" not in text
        def shown() -> str:  # the page redraws on the RigStateChanged message that follows the state
            return str(app.screen.query_one("#rig-connection", Static).render())

        await wait_until(pilot, lambda: "not connected" in shown(), 10, "the Rig page to show it")
        assert f"127.0.0.1:{port}" in shown()
        # starting a sweep without a rig is refused with the way out
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
        await pilot.click("#start")
        await wait_until(pilot, lambda: any("Not connected to the rig" in n for n in notes(app)), what="the refusal")
        assert app.sweep.status == "idle"


def test_a_beam_break_during_a_sweep_is_reported_and_the_drives_stop(cfg, size, connected, wait_until, notes):
    asyncio.run(_beam_break(cfg, size, connected, wait_until, notes))


async def _beam_break(cfg, size, connected, wait_until, notes):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
        app.screen.query_one("#legs", Input).value = "5"
        app.screen.query_one("#cycles", Input).value = "1"
        await pilot.pause()
        app.rig.sim.laser_server.set_beam_break(5, True)  # the beam is blocked before the first reading
        await pilot.click("#start")
        await wait_until(pilot, lambda: app.sweep.status == "failed", 60, "the sweep to give up")
        assert any("beam_break (gave up)" == n.title for n in app._notifications)
        assert app.sweep.faults and app.sweep.faults[-1].gave_up and app.sweep.faults[-1].kind == "beam_break"
        status = app.screen.query_one("#sweep-status", Static)
        await wait_until(pilot, lambda: "failed" in str(status.render()), what="the status line")
        assert "beam" in str(status.render()).lower()
        st = app.rig.axes[5].status()
        assert not st.moving and not st.enabled
        s = read_session(app.sweep.out)
        assert s.attrs["outcome"] == "failed" and len(s.faults) == len(app.sweep.faults)
