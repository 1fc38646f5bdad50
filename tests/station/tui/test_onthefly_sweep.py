"""The Sweep page offers the on-the-fly plans (the same PlanSpec as `station sweep --plan
onthefly...`), runs one on the simulated rig with progress, and shows why an adaptive sweep
stopped a leg."""

from __future__ import annotations

import asyncio

import pytest
from textual.widgets import Input, Static

from procedures.acquisition.plan_spec import plan_from_spec
from procedures.acquisition.plan_spec import DEFAULT_CYCLES
from station.cli import build_parser
from station.commands.sweep import plan_spec as cli_plan_spec
from station.tui.app import StationApp
from tests.station.tui.steps import choose_plan

pytestmark = pytest.mark.timeout(180)


def test_sweep_page_runs_an_adaptive_onthefly_plan_and_says_why_it_stopped(cfg, size, connected, wait_until):
    asyncio.run(_run(cfg, size, connected, wait_until))


async def _run(cfg, size, connected, wait_until):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
        screen = app.screen
        await choose_plan(pilot, "onthefly-adaptive")  # (waits for the page's answer to the choice)
        most = str(DEFAULT_CYCLES["onthefly-adaptive"])
        assert screen.query_one("#cycles", Input).value == most  # the plan's most cycles
        assert screen.query_one("#n-targets", Input).disabled  # positions come from the step
        screen.query_one("#step", Input).value = "2"
        screen.query_one("#legs", Input).value = "1"
        await pilot.pause()
        cli = cli_plan_spec(build_parser("sweep").parse_args(
            ["sweep", "--sim", "--plan", "onthefly-adaptive", "--legs", "1", "--cycles", most, "--step", "2"]))
        assert screen.plan_spec() == cli
        plan = screen.build_plan()
        assert plan == plan_from_spec(cli) and plan.onthefly and plan.adaptive
        text = str(screen.query_one("#plan-summary", Static).render())
        assert "on the fly at 10 and 20 mm/s" in text and "at most" in text
        await pilot.click("#start")
        await wait_until(pilot, lambda: app.sweep.status == "completed", timeout_s=120, what="the sweep to complete")
        s = app.sweep
        assert len(s.stops) == 1 and s.stops[0].leg == 1
        assert len(s.probe_stops) == 1 and s.probe_stops[0].leg == 1  # the adaptive probe count's stop
        # progress counted to the end: the planned total shrank by what the stops made unneeded
        assert s.done == s.total == plan.total_points - s.stops[0].skipped_points - s.probe_stops[0].skipped_points
        await pilot.pause()
        shown = str(screen.query_one("#sweep-faults", Static).render())
        assert f"leg 1: stopped after {s.stops[0].cycles} cycles" in shown
        # the probes' stop came last: shown with the page's next redraw (they are throttled)
        await wait_until(pilot, lambda: f"leg 1: {s.probe_stops[0].pairs} pairs: " in str(
            screen.query_one("#sweep-faults", Static).render()), timeout_s=5, what="the probes' stop shown")
