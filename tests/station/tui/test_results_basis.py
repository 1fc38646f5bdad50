"""The Results page fits and evaluates the same error as `station fit` and `station iso230`:
normalised to 20 degC material temperature by default, raw after `t` (their `--raw`), chosen by
the same function (procedures.metrology.thermal.error_basis). Every figure the page shows is
compared with what the commands write on the same session, on both bases; and the two bases
differ on this session (its legs warm by about 0.2 K), so the comparison can tell them apart.

The Diagnosis page shows the material temperature range the report carries."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest
from textual.widgets import DataTable, Input, Static

from procedures.fit import load_model
from procedures.metrology.thermal import error_basis
from procedures.metrology.uncertainty import UncertaintyInputs, leg_budget
from procedures.io.recording.reader import read_session
from station.cli import main
from station.tui.app import StationApp
from tests.station.tui.steps import open_session

pytestmark = pytest.mark.timeout(180)


def _cli(tmp_path, session, raw: bool) -> dict:
    """`station fit` and `station iso230 --json` on `session` (with `--raw` when raw): the model,
    the ISO 230-2 values and the error-basis lines both printed."""
    tag = "raw" if raw else "norm"
    flag = ["--raw"] if raw else []
    model_path, iso_path = tmp_path / f"model-{tag}.json", tmp_path / f"iso-{tag}.json"
    assert main(["fit", str(session), "--out", str(model_path), *flag]) == 0
    assert main(["iso230", str(session), "--json", str(iso_path), *flag]) == 0
    return {"model": load_model(model_path), "iso": json.loads(iso_path.read_text())}


def test_results_page_uses_the_clis_error_basis_and_t_switches_to_raw(recorded_session, cfg, wait_until, tmp_path,
                                                                       capsys):
    cli = {raw: _cli(tmp_path, recorded_session, raw) for raw in (False, True)}
    printed = capsys.readouterr().out
    asyncio.run(_basis(recorded_session, cfg, wait_until, cli, printed))


def _cells(app) -> dict[int, dict[str, str]]:
    table = app.screen.query_one("#results-table", DataTable)
    labels = [str(c.label) for c in table.columns.values()]
    return {int(row[0]): dict(zip(labels, row)) for row in (table.get_row_at(i) for i in range(table.row_count))}


def _check_against_cli(app, session, cli: dict, raw: bool) -> dict[int, dict[str, float]]:
    """The page's figures are the commands' on this basis; returns the ISO values shown."""
    a = app.analysis
    assert a.raw is raw
    points, lines, basis = error_basis(session, raw)
    # the basis: the same lines as the commands print, the model carrying it as `station fit` saves it
    assert list(a.basis_lines) == lines
    assert a.model.options["error_basis"] == cli["model"].options["error_basis"] == json.loads(json.dumps(basis))
    np.testing.assert_array_equal(a.points["error_um"], points["error_um"])
    cells = _cells(app)
    shown = {}
    for leg, lf in cli["model"].legs.items():
        row = cells[leg]
        assert row["Noise floor"] == f"{lf.stats.noise_floor_um:.3f}"
        assert row["Held-out RMS"] == f"{lf.stats.heldout_rms_um:.3f}"
        grid = np.linspace(-80.0, 80.0, 41)
        for d in (1, -1):  # the same model, not only the same summary figures
            np.testing.assert_allclose(a.model.predict_um(leg, grid, d), cli["model"].predict_um(leg, grid, d),
                                       rtol=0, atol=1e-9)
        iso = cli["iso"]["legs"][str(leg)]
        inputs = UncertaintyInputs.from_record(session.station_config, leg)
        from procedures.reporting import iso230

        budget = leg_budget(iso230.evaluate(points)[leg], points, inputs)
        shown[leg] = {}
        for name in "AEMBR":
            value, u = row[name].split("\n")
            assert value == f"{iso[name]:.3f}", (leg, name, raw)
            assert u == f"±{budget.U(name):.3f}"
            shown[leg][name] = iso[name]
    return shown


async def _basis(path, cfg, wait_until, cli, printed):
    session = read_session(path)
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=(130, 40)) as pilot:
        await open_session(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        status = lambda: str(app.screen.query_one("#results-status", Static).render())  # noqa: E731
        # 1) the default: normalised to 20 degC, as the commands without --raw
        norm = _check_against_cli(app, session, cli[False], raw=False)
        norm_lines = error_basis(session, False)[1]
        assert norm_lines[0] in printed  # the line the commands printed ...
        assert norm_lines[0].split(" (")[0] in status()  # ... heads the page's basis line
        basis = app.analysis.basis
        temps = basis["material_temp_range_c"].values()
        corr = basis["correction_range_um"].values()
        assert (f"error: normalised to 20 degC material temperature, legs 1, 2: material "
                f"{min(t[0] for t in temps):.2f}..{max(t[1] for t in temps):.2f} °C, correction "
                f"{min(c[0] for c in corr):+.3f}..{max(c[1] for c in corr):+.3f} µm  (t: raw)") in status()
        # the commands' full lines (each leg's range and correction) are the status' tooltip
        assert str(app.screen.query_one("#results-status", Static).tooltip) == "\n".join(norm_lines)
        # the key is in the help (the footer has no room for it at 80 columns)
        from station.tui.screens.help import help_text

        assert "[b]t[/b] Error raw / normalised to 20 °C (--raw)" in help_text(app)
        # 2) t: the raw error, as --raw
        await pilot.press("t")
        await wait_until(pilot, lambda: app.analysis.raw, 60, "the fit on the raw error")
        raw = _check_against_cli(app, session, cli[True], raw=True)
        assert "error: raw, not normalised to 20 degC  (t: normalise to 20 °C)" in status()
        assert "error: normalised" not in status()
        # the two bases give different figures on this session: the comparisons above could fail
        assert any(abs(norm[leg]["E"] - raw[leg]["E"]) > 0.01 for leg in norm)
        # 3) the method keeps the basis; t again goes back to 20 degC
        await pilot.press("m")
        await wait_until(pilot, lambda: app.analysis.method == "paper", 60, "the paper fit")
        assert app.analysis.raw
        await pilot.press("t")
        await wait_until(pilot, lambda: not app.analysis.raw, 60, "the fit normalised again")
        assert app.analysis.method == "paper"
        assert _cells(app)[1]["E"].split("\n")[0] == f"{norm[1]['E']:.3f}"


def test_diagnosis_page_shows_the_material_temperature_range(recorded_session, cfg, wait_until, tmp_path):
    asyncio.run(_diagnosis(recorded_session, cfg, wait_until, tmp_path))


async def _diagnosis(path, cfg, wait_until, tmp_path):
    out = tmp_path / "diag.json"
    assert main(["diagnose", str(path), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())["material_temperature"]
    assert set(doc["legs"]) == {"1", "2"}
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=(130, 40)) as pilot:
        await pilot.press("f6")
        await wait_until(pilot, lambda: app.screen.query("#session-path"), what="the session picker")
        app.screen.query_one("#session-path", Input).value = str(path)
        await pilot.click("#session-open")
        await wait_until(pilot, lambda: app.screen.report is not None, 90, "the diagnosis")
        assert app.screen.report["material_temperature"] == doc
        status = str(app.screen.query_one("#diag-status", Static).render())
        lo = min(v["min_c"] for v in doc["legs"].values())
        hi = max(v["max_c"] for v in doc["legs"].values())
        far = max(v["max_from_reference_k"] for v in doc["legs"].values())
        assert hi - lo > 0.05 and far > 0.05  # the legs warmed: the line has something to say
        assert (f"raw error (not normalised to 20 °C); material {lo:.2f}..{hi:.2f} °C on legs 1, 2, "
                f"up to {far:.2f} K from 20 °C") in status
        # each leg's range ends the text, as `station diagnose` prints it
        text = str(app.screen.query_one("#diag-text", Static).render())
        for leg, v in doc["legs"].items():
            assert f"leg {leg}: {v['min_c']:.2f} .. {v['max_c']:.2f} degC" in text
