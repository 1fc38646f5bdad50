"""The History page (F8): a serial typed in shows what `station history` computes from the same
catalog (rows, E/B/M with U, due date), and a plot of E and B over the calibrations."""

from __future__ import annotations

import asyncio

import pytest
from textual.widgets import DataTable, Input, Static

from station.catalog import files
from station.catalog.history import history
from station.catalog.store import catalog_of
from station.tui.app import StationApp
from station.tui.widgets import XYPlot
from tests.catalog.helpers import write_session

pytestmark = pytest.mark.timeout(120)


def test_history_page_shows_a_legs_history(cfg, size, wait_until):
    runs = cfg.recordings_dir
    from pathlib import Path

    Path(runs).mkdir(parents=True)
    write_session(Path(runs) / "c1.h5", {2: "HX-0042"}, started_utc="2026-02-01T10:00:00.000000Z", seed=1)
    write_session(Path(runs) / "c2.h5", {2: "HX-0042"}, started_utc="2026-05-01T10:00:00.000000Z", seed=2)
    catalog = catalog_of(cfg)
    files.index(catalog, [runs])
    expected = history(catalog.engine, "HX-0042", cfg.catalog.calibration_interval_days)
    assert len(expected.calibrations) == 2
    asyncio.run(_history(cfg, size, wait_until, expected))


async def _history(cfg, size, wait_until, expected):
    app = StationApp(cfg, autoconnect=False, hide_volatile=True)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f8")
        await wait_until(pilot, lambda: getattr(app.screen, "MODE", "") == "history", what="the History page")
        screen = app.screen
        field = screen.query_one("#hist-serial", Input)
        field.focus()  # as a click in the field does
        field.value = "HX-0042"
        await pilot.press("enter")
        table = screen.query_one("#hist-table", DataTable)
        await wait_until(pilot, lambda: table.row_count == len(expected.rows), 30, "the history rows")
        for i, r in enumerate(expected.rows):
            row = table.get_row_at(i)
            e = r.figures["E"]
            assert row[0] == r.time_utc[:19] and row[1] == "session"
            assert row[4] == f"{e['value_um']:.2f}±{e['U_um']:.2f}"
        status = str(screen.query_one("#hist-status", Static).render())
        assert f"due {expected.due}" in status and "2 calibration(s)" in status
        assert screen.query_one("#hist-plot", XYPlot).drawn_series == ["E", "B"]
        # a serial the catalog does not know says so
        field.focus()
        field.value = "NOPE"
        await pilot.press("enter")
        await wait_until(pilot, lambda: "no records" in str(screen.query_one("#hist-status", Static).render()), 30,
                         "the unknown serial")
        assert table.row_count == 0
