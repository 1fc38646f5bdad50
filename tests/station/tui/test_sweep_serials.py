"""The Sweep page's Serials field: each selected leg's serial, recorded in the session like
`station sweep --serial`; a serial for a leg not swept, or not a serial, is refused before the
start (simulated rig at time scale 0, real Modbus TCP and serial pty)."""

from __future__ import annotations

import asyncio

import pytest
from textual.widgets import Input

from procedures.io.recording.reader import read_identity
from station.tui.app import StationApp

pytestmark = pytest.mark.timeout(120)


async def _form(pilot, connected, wait_until, legs: str, serials: str) -> None:
    app = pilot.app
    await connected(pilot)
    await pilot.press("f2")
    await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
    for wid, value in (("legs", legs), ("cycles", "1"), ("n-targets", "5"), ("serials", serials)):
        app.screen.query_one(f"#{wid}", Input).value = value
    await pilot.pause()


def test_serials_entered_on_the_sweep_page_are_recorded(cfg, size, connected, wait_until):
    async def go():
        app = StationApp(cfg, time_scale=0.0)
        async with app.run_test(size=size) as pilot:
            await _form(pilot, connected, wait_until, "1,3", "1=HX-0001, 3=HX-0042")
            await pilot.click("#start")
            await wait_until(pilot, lambda: app.sweep.status == "completed", what="the sweep to complete")
            ident = read_identity(app.sweep.out)
            assert (ident.leg_serial(1), ident.leg_serial(3)) == ("HX-0001", "HX-0042")
            assert ident.leg(3).drive.source == "modbus-device-id"
    asyncio.run(go())


@pytest.mark.parametrize("serials, reason", [("2=HX-1", "not swept"), ("1=HX#1", "not a serial number"), ("1", "write LEG=SERIAL")])
def test_a_bad_serial_is_refused_before_the_start(cfg, size, connected, wait_until, serials, reason):
    async def go():
        app = StationApp(cfg, time_scale=0.0)
        async with app.run_test(size=size) as pilot:
            await _form(pilot, connected, wait_until, "1", serials)
            await pilot.click("#start")
            # the refusal comes as the press is handled (under load, after Pilot's idle check)
            await wait_until(pilot, lambda: any(reason in str(n.message) for n in app._notifications), 10,
                             f"the refusal naming {reason!r}")
            assert app.sweep.status == "idle"
    asyncio.run(go())
