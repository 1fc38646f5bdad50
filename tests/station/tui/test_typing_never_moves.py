"""No key that moves a leg can be reached by typing a value (issue 22, item 1).

Every printable character is typed, key by key, into every text field of every page (Rig,
Sweep, Results, Compensation, Replay, Diagnosis, Platform) and of the dialogs that have one (the
Sweep page's Resume), with all six legs enabled on the simulated rig. The drives are asked
nothing: the simulated drive server (a real Modbus server on loopback) counts the set-points it
latched, and that count does not change, nor does a sweep start. Stop all (x) may act from the
Rig page's fields (a stop never moves a leg): the legs are enabled again after it.
"""

from __future__ import annotations

import asyncio
import string
import time

import pytest
from textual.widgets import Input

from station.tui.app import StationApp
from station.tui.screens.common import PAGES

pytestmark = pytest.mark.timeout(400)

LEGS = (1, 2, 3, 4, 5, 6)
# string.printable without its control characters (tab, newline, return, vertical tab, form feed);
# x (Stop all, which acts from the Rig page's fields) last, so every other key meets enabled legs
TYPED = [c for c in string.printable if c.isprintable() and c != "x"] + ["x"]
PAGE_KEYS = {mode: key.lower() for mode, key, _ in PAGES}


def set_points(app) -> dict[int, int]:
    """Set-points each simulated drive has latched (moves started or refused), read at the server."""
    server = app.rig.sim.drive_server
    return {leg: server.set_points(leg) for leg in LEGS}


async def enable_all(pilot, wait_until) -> None:
    app = pilot.app
    app.rig_action("enable", LEGS)

    def enabled() -> bool:
        with app.rig_lock:
            return all(app.rig.axes[leg].status().enabled for leg in LEGS)

    await wait_until(pilot, enabled, what="all legs enabled")


async def type_everything(pilot, field: Input, focus: bool = True) -> None:
    """Type every printable character, one key at a time, into `field` (focused first, unless
    `focus` is False: then where the focus is, which must be `field`)."""
    if focus:
        field.focus()
        await pilot.pause()
    assert pilot.app.focused is field, f"#{field.id} does not have the focus"
    await pilot.press(*TYPED)


def fields_of(screen) -> list[Input]:
    return [f for f in screen.query(Input).results(Input) if not f.disabled and f.display]


def test_typing_into_every_field_of_every_page_never_moves_a_leg(cfg, size, connected, wait_until, rig_keys_act):
    asyncio.run(_type_everywhere(cfg, size, connected, wait_until, rig_keys_act))


async def _type_everywhere(cfg, size, connected, wait_until, rig_keys_act):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.2)
    typed_into: list[str] = []
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await enable_all(pilot, wait_until)
        # a target typed and entered moves leg 1 (one set-point); the field keeps the focus, so
        # what is typed next (the "-" of "-25" first) goes to the field, not to the jog keys
        target = app.screen.query_one("#move-target", Input)
        target.focus()
        await pilot.press("5", "enter")
        await wait_until(pilot, lambda: "leg 1 at +5.0000 mm" in app.rig_motion_text, what="the move to 5 mm")
        assert app.focused is target
        target.value = ""
        before = set_points(app)
        for mode, key in PAGE_KEYS.items():
            await pilot.press(key)
            await wait_until(pilot, lambda: app.screen.MODE == mode, what=f"the {mode} page")
            fields = fields_of(app.screen)
            assert fields or mode == "rig", f"the {mode} page has no text field to type into"
            for field in fields:
                # the target field just entered: typed into without touching the focus
                await type_everything(pilot, field, focus=field is not target)
                typed_into.append(f"{mode}#{field.id}")
                assert set_points(app) == before, f"typing into {mode}#{field.id} moved a leg"
                assert not app.rig_motion and not app.sweep.active, f"typing into {mode}#{field.id} started motion"
                if mode == "rig":  # x (Stop all) acts from the move fields: enable again for the next field
                    await enable_all(pilot, wait_until)
            if mode == "sweep":  # the Resume dialog's path field
                left = time.monotonic()
                await pilot.press("escape")
                await rig_keys_act(pilot, left)  # r on its own (RIG_KEYS), not right after a field
                await pilot.press("r")
                await wait_until(pilot, lambda: app.screen.query("#resume-path"), what="the Resume dialog")
                for field in fields_of(app.screen):
                    await type_everything(pilot, field)
                    typed_into.append(f"resume-dialog#{field.id}")
                await pilot.press("escape")
                await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the dialog closed")
        await pilot.pause(0.3)  # anything a key started would have reached the drives by now
        assert set_points(app) == before
        assert not app.rig_motion and not app.sweep.active
    # every page's fields were typed into (the rig's two, the sweep form's, each picker's, ...)
    assert {"rig#move-target", "rig#move-speed", "sweep#step", "resume-dialog#resume-path", "results#session-path",
            "compensation#comp-step", "replay#replay-speed", "diagnosis#twin-spec", "platform#plat-poses"} \
        <= set(typed_into), typed_into
