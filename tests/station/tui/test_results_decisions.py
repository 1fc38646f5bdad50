"""The Results page states each leg's ISO 14253-1 decision when the session's config stated
tolerances for the leg's type (docs/decisions.md), and nothing when it did not."""

from __future__ import annotations

import asyncio

import pytest
from textual.widgets import Static

from station.tui.app import StationApp
from tests.station.tui.steps import open_session
from tests.tooling import default_legs_points, write_identified_session

pytestmark = pytest.mark.timeout(120)


async def _status(cfg, wait_until, path) -> str:
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=(130, 40)) as pilot:
        await open_session(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, what="the analysis")
        await pilot.pause()
        return str(app.screen.query_one("#results-status", Static).render())


def test_results_page_shows_the_decision(cfg, wait_until, tmp_path):
    points = default_legs_points(legs=(1,), cycles=3, step_mm=15.0)
    tol = {"HX300": {"as_found_um": {"E": 1000.0, "B": 0.001}, "as_left_um": {}, "source": "t"}}
    stated = write_identified_session(tmp_path / "stated.h5", points, station_config={"tolerances": tol})
    plain = write_identified_session(tmp_path / "plain.h5", points)
    text = asyncio.run(_status(cfg, wait_until, stated))
    assert "as-found (ISO 14253-1): leg 1 DOES NOT CONFORM (B " in text and "vs 0.001 µm" in text
    assert "ISO 14253-1" not in asyncio.run(_status(cfg, wait_until, plain))


def test_compensation_page_line_for_a_verification(tmp_path):
    # the page shows "as-left (ISO 14253-1): " + the verification job's summary (Verification.as_left_summary,
    # station/services/verify_job.py), the decision_summary of the session's as-left decisions; the job's
    # decisions equal those of its recording read back (tests/station/test_cli_verify_decisions.py)
    from procedures.io.recording.reader import read_session
    from procedures.reporting.decision import decision_summary
    from station.services.report_jobs import decisions_if_stated

    points = default_legs_points(legs=(1,), cycles=3, step_mm=15.0)
    tol = {"HX300": {"as_found_um": {"E": 1000.0}, "as_left_um": {"E": 0.001}, "source": "t"}}
    ver = read_session(write_identified_session(tmp_path / "ver.h5", points, station_config={"tolerances": tol}))
    text = decision_summary(decisions_if_stated(ver, stage="as_left")["legs"])
    assert text.startswith("leg 1 DOES NOT CONFORM (E ") and "vs 0.001 µm" in text
    plain = read_session(write_identified_session(tmp_path / "plain.h5", points))
    assert decisions_if_stated(plain, stage="as_left") is None  # no tolerance stated: no line on the page
