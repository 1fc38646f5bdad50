"""Rig page: move a leg to a position at a speed, jog it by a step; refused beyond the soft
limits, on a leg in fault or not enabled, and while a sweep holds the rig (running or paused);
Stop all (x) ends a move at once. Simulated rig, real Modbus TCP + serial pty."""

from __future__ import annotations

import asyncio
import time

import pytest
from textual.widgets import DataTable, Input, Select, Static

from tests.tooling import start_paper_sweep
from station.tui.app import StationApp

pytestmark = pytest.mark.timeout(180)


def position(app, leg: int) -> float:
    return app.rig.axes[leg].status().position_mm


def motion_text(app) -> str:
    return str(app.screen.query_one("#move-status", Static).render())


async def type_into(pilot, wid: str, text: str) -> None:
    field = pilot.app.screen.query_one(f"#{wid}", Input)
    field.value = text
    await pilot.pause()


async def select_leg(pilot, leg: int) -> None:
    table = pilot.app.screen.query_one("#drives", DataTable)
    table.focus()
    table.move_cursor(row=table.get_row_index(str(leg)))
    await pilot.pause()


def test_move_to_a_position_at_a_speed_and_jog_by_steps(cfg, size, connected, wait_until, notes, rig_keys_act):
    asyncio.run(_move_and_jog(cfg, size, connected, wait_until, notes, rig_keys_act))


async def _move_and_jog(cfg, size, connected, wait_until, notes, rig_keys_act):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.1)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        # the soft limits and the default speed (a quarter of the drive's maximum) are shown
        await wait_until(pilot, lambda: "soft limits -95.000 .. +95.000 mm" in motion_text(app), what="the limits")
        assert "max 20 mm/s" in motion_text(app) and "blank speed: 5 mm/s" in motion_text(app)
        assert app.screen.query_one("#move-speed", Input).placeholder == "5"

        # m with no target says so and puts the cursor in the target field: the digits typed next go there
        await pilot.press("m")
        await wait_until(pilot, lambda: any("type a target position in mm" in n for n in notes(app)),
                         what="the request for a target")
        assert app.focused is app.screen.query_one("#move-target", Input)
        await pilot.press("3", "0")
        await wait_until(pilot, lambda: app.screen.query_one("#move-target", Input).value == "30",
                         what="the digits typed into the target field")
        left = time.monotonic()
        app.screen.query_one("#drives", DataTable).focus()
        # a rig key right after a field lost the focus is ignored (it may be typing meant for the
        # field: StationScreen.RIG_KEYS); a moment later it acts
        await rig_keys_act(pilot, left)
        # a disabled leg is refused, with what to do
        await type_into(pilot, "move-target", "30")
        await pilot.press("m")
        await wait_until(pilot, lambda: any("leg 1 is disabled, not enabled: enable it (e) first" in n
                                            for n in notes(app)), what="the refusal of a disabled leg")
        assert position(app, 1) == pytest.approx(0.0, abs=1e-6)

        await pilot.press("e")
        await wait_until(pilot, lambda: app.rig.axes[1].status().enabled, what="leg 1 enabled")
        # to 30 mm at 2 mm/s, from the field (Enter)
        await type_into(pilot, "move-speed", "2")
        app.screen.query_one("#move-target", Input).focus()
        await pilot.press("enter")
        await wait_until(pilot, lambda: any("leg 1 at +30.0000 mm (moved at 2 mm/s)" in n for n in notes(app)),
                         what="the move to 30 mm")
        assert position(app, 1) == pytest.approx(30.0, abs=1e-6)
        target = app.screen.query_one("#move-target", Input)
        assert app.focused is target, "the target field keeps the focus after its Enter"
        # the next target typed goes into the field: its - is not a jog, its digits are not lost
        moves = app.rig.sim.drive_server.set_points(1)
        await type_into(pilot, "move-target", "")
        await pilot.press("minus", "2", "5")
        await wait_until(pilot, lambda: target.value == "-25", what="-25 typed into the target field")
        assert app.focused is target
        await pilot.pause(0.2)
        assert app.rig.sim.drive_server.set_points(1) == moves and not app.rig_motion
        assert position(app, 1) == pytest.approx(30.0, abs=1e-6)
        left = time.monotonic()
        await pilot.press("escape")  # out of the field: the motion keys act again
        await wait_until(pilot, lambda: isinstance(app.focused, DataTable), what="Esc to leave the field")
        # the drive's own profile velocity is back for the sweeps that follow
        reg = app.rig.profile.registers["profile_velocity"]
        ax = app.rig.axes[1]
        assert reg.decode(ax.bus.read(ax.unit, reg.address, reg.words)) == pytest.approx(10.0)

        # jogs: +1 mm (the default step), then the step is 10 mm (j), -10 mm; blank speed = default
        await type_into(pilot, "move-speed", "")
        # a rig key within STRAY_HOLD_S of leaving a text field is taken for typing (docs/tui.md "Keys")
        await rig_keys_act(pilot, left)
        await pilot.press("plus")
        await wait_until(pilot, lambda: any("leg 1 at +31.0000 mm (moved at 5 mm/s)" in n for n in notes(app)),
                         what="the jog +1 mm")
        await pilot.press("j")
        await wait_until(pilot, lambda: app.screen.query_one("#jog-step", Select).value == 10.0, what="the 10 mm step")
        await pilot.press("minus")
        await wait_until(pilot, lambda: any("leg 1 at +21.0000 mm" in n for n in notes(app)), what="the jog -10 mm")
        assert position(app, 1) == pytest.approx(21.0, abs=1e-6)
        await wait_until(pilot, lambda: "last move: leg 1 at +21.0000 mm" in motion_text(app), what="the last move shown")

        # beyond the soft limits: refused before anything moves, naming the limits
        await type_into(pilot, "move-target", "96")
        await pilot.press("m")
        await wait_until(pilot, lambda: any("leg 1 target: '96' is outside -95 .. 95 mm" in n and "soft limits" in n
                                            and "nothing moved" in n for n in notes(app)),
                         what="the refusal beyond the limits")
        await type_into(pilot, "move-target", "90")
        await pilot.press("m")
        await wait_until(pilot, lambda: any("leg 1 at +90.0000 mm" in n for n in notes(app)), what="the move to 90 mm")
        await pilot.press("plus")  # +10 mm from 90 mm: the worker refuses it against the drive's limits
        await wait_until(pilot, lambda: any("a jog of +10 mm from +90.000 mm" in n and "-95.000 .. +95.000 mm" in n
                                            for n in notes(app)), what="the refusal of the jog")
        assert position(app, 1) == pytest.approx(90.0, abs=1e-6)
        # a bad speed is refused on the page
        await type_into(pilot, "move-speed", "0")
        await pilot.press("m")
        await wait_until(pilot, lambda: any("speed: '0' is outside >0 .. 1000 mm/s" in n for n in notes(app)), what="the speed refusal")
        await type_into(pilot, "move-speed", "")

        # a leg in fault is refused: reset it first
        app.rig.sim.drive_server.inject_fault(1, "overcurrent")
        await type_into(pilot, "move-target", "0")
        await pilot.press("m")
        await wait_until(pilot, lambda: any("leg 1 is in fault: reset the fault (r), then enable it (e), first" in n
                                            for n in notes(app)), what="the refusal of a leg in fault")
        # another leg: the move acts on the selected row
        await select_leg(pilot, 2)
        # the target typed (0) is shown for the leg selected now, with its soft limits, before it moves
        await wait_until(pilot, lambda: "leg 2 → +0.000 mm" in motion_text(app)
                         and "soft limits -95.000 .. +95.000 mm" in motion_text(app), what="leg 2 selected")
        await pilot.press("e")
        await wait_until(pilot, lambda: app.rig.axes[2].status().enabled, what="leg 2 enabled")
        await type_into(pilot, "move-target", "-12.5")
        await pilot.press("m")
        await wait_until(pilot, lambda: any("leg 2 at -12.5000 mm" in n for n in notes(app)), what="the move of leg 2")
        assert position(app, 2) == pytest.approx(-12.5, abs=1e-6)


def test_stop_all_ends_a_move_at_once(cfg, size, connected, wait_until, notes, rig_keys_act):
    asyncio.run(_stop(cfg, size, connected, wait_until, notes, rig_keys_act))


async def _stop(cfg, size, connected, wait_until, notes, rig_keys_act):
    # 1 simulated s = 50 ms: 80 mm at 0.2 mm/s take 20 s (a key press waits up to 2 s for the app
    # to be idle, and a move polls its drive busily)
    app = StationApp(cfg, time_scale=0.05, poll_interval_s=0.2)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await pilot.press("e")
        await wait_until(pilot, lambda: app.rig.axes[1].status().enabled, what="leg 1 enabled")
        await type_into(pilot, "move-target", "80")
        await type_into(pilot, "move-speed", "0.2")
        await pilot.press("m")
        await wait_until(pilot, lambda: app.rig.axes[1].status().moving, what="leg 1 moving")
        await wait_until(pilot, lambda: "leg 1 moving to +80.000 mm at 0.2 mm/s" in motion_text(app),
                         what="the move shown")
        # another move is refused while this one runs
        await pilot.press("plus")
        await wait_until(pilot, lambda: any("Leg 1 is still moving" in n for n in notes(app)), what="the second refused")
        # x stops it, also from inside a move field
        app.screen.query_one("#move-target", Input).focus()
        # t0 before the position is read: the leg moves on between the two, and the bound below
        # must count that time (under load a read can take longer than the 0.01 mm slack allows)
        t0 = time.monotonic()
        before = position(app, 1)
        assert app.rig_motion and 0.0 < before < 80.0
        await pilot.press("x")
        await wait_until(pilot, lambda: not app.rig_motion, 10, "the move to end")
        elapsed = time.monotonic() - t0
        st = app.rig.axes[1].status()
        assert not st.moving and st.state == "quick_stop_active"
        # stopped at once: no further than the leg goes while the key press is handled
        assert before <= st.position_mm <= before + 0.2 * elapsed / 0.05 + 0.01 < 80.0
        await pilot.pause(0.3)
        assert position(app, 1) == pytest.approx(st.position_mm, abs=1e-6), "it stays stopped"
        assert app.screen.query_one("#move-target", Input).value == "80", "x stopped, it did not type"
        assert any(f"leg 1 was quick-stopped at {st.position_mm:+.3f} mm on its way to +80.000 mm; enable it (e)" in n
                   for n in notes(app))
        await wait_until(pilot, lambda: "quick-stopped" in motion_text(app), what="the stop shown")
        # enabled again: the quick stop's toast goes (it no longer says what to do)
        left = time.monotonic()
        await pilot.press("escape")  # leave the field; its letters act a moment later (RIG_KEYS)
        await rig_keys_act(pilot, left)
        await pilot.press("e")
        await wait_until(pilot, lambda: app.rig.axes[1].status().enabled, what="leg 1 enabled again")
        await wait_until(pilot, lambda: not any("quick-stopped" in n for n in notes(app)), what="the toast cleared")


def test_moves_are_refused_while_a_sweep_runs_or_is_paused(cfg, size, connected, wait_until, notes):
    asyncio.run(_refused_during_sweep(cfg, size, connected, wait_until, notes))


async def _refused_during_sweep(cfg, size, connected, wait_until, notes):
    # 1 simulated s = 20 ms: the paper plan (dwell 1 s a point) runs for minutes, long enough to act
    app = StationApp(cfg, time_scale=0.02, poll_interval_s=0.1)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")
        await start_paper_sweep(pilot, "3")
        await wait_until(pilot, lambda: app.sweep.done >= 3, what="first points")
        await pilot.press("f1")
        await wait_until(pilot, lambda: app.screen.MODE == "rig", what="the Rig page")
        await type_into(pilot, "move-target", "10")
        await pilot.press("m")
        await wait_until(pilot, lambda: any("A sweep is running: abort it first (a on the Sweep page, F2)" in n
                                            for n in notes(app)), what="the refusal while running")
        app.action_pause_sweep()
        await wait_until(pilot, lambda: app.sweep.status == "paused", what="the pause")
        app.clear_notifications()
        await pilot.press("plus")
        await wait_until(pilot, lambda: any("The sweep is paused, and a paused sweep still holds the rig: abort it (a), "
                                            "or resume it (p) and let it finish, first" in n for n in notes(app)),
                         what="the refusal while paused")
        assert not any("pause or abort" in n for n in notes(app))
        assert not app.rig_motion
        await pilot.press("e")  # the other rig actions say the same
        await wait_until(pilot, lambda: sum("paused sweep still holds the rig" in n for n in notes(app)) >= 2,
                         what="the refusal of enable")
        assert "sweep paused" in str(app.screen.query_one("#rig-connection", Static).render())
        app.action_abort_sweep()
        await wait_until(pilot, lambda: not app.sweep.active, what="the abort")
