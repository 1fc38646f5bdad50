"""The Results page shows each ISO 230-2 value over its expanded uncertainty U (k = 2), the same
U the budget (procedures.metrology.uncertainty) gives for the session's points and config."""

from __future__ import annotations

import asyncio

import pytest
from textual.widgets import DataTable

from procedures.reporting import iso230
from procedures.metrology.thermal import error_basis
from procedures.metrology.uncertainty import UncertaintyInputs, leg_budget
from procedures.io.recording.reader import read_session
from station.tui.app import StationApp
from tests.station.tui.steps import open_session

pytestmark = pytest.mark.timeout(120)


def test_results_show_U_beside_each_iso_value(recorded_session, cfg, wait_until):
    asyncio.run(_shown(recorded_session, cfg, wait_until))


async def _shown(path, cfg, wait_until):
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=(130, 40)) as pilot:
        await open_session(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        session = read_session(path)
        points = error_basis(session)[0]  # the page's default error, as station iso230's: normalised to 20 degC
        iso = iso230.evaluate(points)
        table = app.screen.query_one("#results-table", DataTable)
        labels = [str(c.label) for c in table.columns.values()]
        for row, leg in enumerate(sorted(iso)):
            budget = leg_budget(iso[leg], points, UncertaintyInputs.from_record(session.station_config, leg))
            cells = dict(zip(labels, table.get_row_at(row)))
            for name in "AEMBR":
                value, u = cells[name].split("\n")
                assert value == f"{iso[leg].values[name]:.3f}"
                assert u == f"±{budget.U(name):.3f}"
                assert budget.U(name) > 0
        assert "±U, k = 2" in str(app.screen.query_one("#results-status").render())
