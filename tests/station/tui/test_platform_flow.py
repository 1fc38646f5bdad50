"""The Platform page (F7): the paper's Table 2 for the analysis on show, or for a table typed in,
against what procedures.platform.experiment and `station platform` compute for the same inputs."""

from __future__ import annotations

import asyncio
import json

import pytest
from textual.widgets import DataTable, Input

from procedures.fit import fit
from procedures.metrology.thermal import error_basis
from procedures.platform.experiment import RecordedLegErrors, run_measurements
from procedures.platform.geometry import default_geometry
from procedures.io.recording.reader import read_session
from station.cli import main
from station.tui.app import StationApp
from station.tui.screens.platform import COMPONENTS
from station.tui.widgets import XYPlot

pytestmark = pytest.mark.timeout(120)

ROWS = ("max_original", "min_original", "max_compensated", "min_compensated", "range_reduction_pct",
        "mean_abs_original", "mean_abs_compensated")
REPORT_FILES = ("platform_report.md", "platform_summary.json", "pose_position_hist.png",
                "pose_orientation_hist.png", "leg_error_hist.png")


async def open_and_fit(pilot, wait_until, path) -> None:
    app = pilot.app
    await pilot.press("f3")
    await wait_until(pilot, lambda: app.screen.query("#session-path"), what="the session picker")
    app.screen.query_one("#session-path", Input).value = str(path)
    await pilot.click("#session-open")
    await wait_until(pilot, lambda: app.analysis is not None and app.analysis.path == path, 60, "the fit")


async def run_platform(pilot, wait_until, poses=None, seed=None, compensation=None, recording=None) -> None:
    app = pilot.app
    await pilot.press("f7")
    await wait_until(pilot, lambda: app.screen.MODE == "platform", what="the Platform page")
    screen = app.screen
    for wid, value in (("#plat-poses", poses), ("#plat-seed", seed), ("#plat-comp", compensation),
                       ("#plat-recording", recording)):
        if value is not None:
            screen.query_one(wid, Input).value = str(value)
    before = screen.platform_run
    await pilot.press("p")
    await wait_until(pilot, lambda: screen.platform_run is not before and screen.platform_run is not None, 60,
                     "the platform experiment")


def shown_pose_table(screen) -> dict[str, list[str]]:
    table = screen.query_one("#plat-table", DataTable)
    return {row[0]: list(row[1:]) for row in (table.get_row_at(i) for i in range(table.row_count))}


def expected_pose_cells(summary: dict, key: str) -> list[str]:
    pose = summary["pose"]
    stats = [pose["x_um"], pose["y_um"], pose["z_um"], pose["rx_arcsec"], pose["ry_arcsec"], pose["rz_arcsec"]]
    if key == "range_reduction_pct":
        return [f"{st[key]:.2f} %" for st in stats]
    return [f"{st[key]:.4f}" for st in stats]


def check_page_against(screen, summary: dict, other: dict) -> None:
    """Table 2 of `summary` (the main measurement), and the leg-vs-pose comparison of both."""
    shown = shown_pose_table(screen)
    assert len(shown) == len(ROWS)
    for (label, cells), key in zip(shown.items(), ROWS):
        assert cells == expected_pose_cells(summary, key), label
    legs = screen.query_one("#plat-legs", DataTable)
    heads = [str(c.label) for c in legs.columns.values()]
    assert heads[1] == "systematic: pose" and heads[4] == "one pass: pose"
    assert legs.row_count == 6
    for i, comp in enumerate(COMPONENTS):
        row = legs.get_row_at(i)
        main_acc, other_acc = summary["acceptance"][comp], other["acceptance"][comp]
        assert row[1:4] == [f"{main_acc['range_reduction_pct']:.2f} %", f"{summary['legs']['all']['range_reduction_pct']:.2f} %",
                            "yes" if main_acc["at_least_leg_reduction"] else "no"]
        assert row[4:7] == [f"{other_acc['range_reduction_pct']:.2f} %", f"{other['leg_range_reduction_pct']:.2f} %",
                            "yes" if other_acc["at_least_leg_reduction"] else "no"]
        dom = summary["dominant_leg"]["original"][i]
        assert row[7].startswith(f"leg {dom['leg']} (") or row[7].startswith("legs ")


def test_platform_page_runs_the_analysis_on_show_and_writes_the_report(six_leg_session, cfg, size, wait_until, notes):
    asyncio.run(_analysis_on_show(six_leg_session, cfg, size, wait_until, notes))


async def _analysis_on_show(path, cfg, size, wait_until, notes):
    app = StationApp(cfg, time_scale=0.0, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await open_and_fit(pilot, wait_until, path)
        await run_platform(pilot, wait_until, poses=500, seed=3)
        screen = app.screen
        # the same experiment, straight from the procedures: the model Results fits, both measurements
        session = read_session(path)
        at_20_c = error_basis(session)[0]
        model = fit(at_20_c, "default")  # fitted, as `station fit`, to the error at 20 degC

        def errors(measurement):
            # measured on the model's basis: the recording's error normalised to 20 degC as well
            return RecordedLegErrors(at_20_c, predicted_um=model.predict_um, measurement=measurement)

        result, summary = run_measurements(default_geometry(), errors("mean"), errors("pass"), poses=500, seed=3)
        other = summary["other_measurement"]
        assert summary["measured"] == "mean" and other["measured"] == "pass"
        assert screen.platform_run.summary["poses"] == 500 and screen.platform_run.summary["seed"] == 3
        assert screen.platform_run.inputs["error_basis"]["basis"] == "normalised"
        assert "error normalised to 20 °C" in str(screen.query_one("#plat-status").render())
        check_page_against(screen, summary, other)
        # one pass adds the scatter no table removes: less reduction at the legs than the systematic error
        assert other["leg_range_reduction_pct"] < summary["legs"]["all"]["range_reduction_pct"]
        # the histograms of the highlighted component, then the next one
        plots = screen.query_one("#plat-plot-orig", XYPlot), screen.query_one("#plat-plot-comp", XYPlot)
        assert [p.drawn_series for p in plots] == [["original"], ["compensated"]]
        assert all(p.drawn_points == 80 for p in plots)  # 40 bins, two corners each
        assert screen.component == "x_um"
        await pilot.press("c")
        await wait_until(pilot, lambda: screen.component == "y_um", what="the next component")
        assert screen.query_one("#plat-legs", DataTable).cursor_row == 1
        # w: the CLI's files beside the session, in platform/<session>/
        await pilot.press("w")
        out = path.parent / "platform" / path.stem
        await wait_until(pilot, lambda: screen.platform_run.written, 60, "the report files")
        assert [p.name for p in screen.platform_run.written] == list(REPORT_FILES)
        assert all((out / name).stat().st_size > 0 for name in REPORT_FILES)
        # the toast is a message the app handles after `written` is set: waited for, not raced
        await wait_until(pilot, lambda: any("Platform report written" in n for n in notes(app)), what="the toast")
        written = json.loads((out / "platform_summary.json").read_text())
        assert written["poses"] == 500 and written["seed"] == 3 and written["measured"] == "mean"
        assert written["pose"] == json.loads(json.dumps(summary["pose"]))
        assert written["other_measurement"]["acceptance"] == other["acceptance"]
        assert written["inputs"]["recording"] == {"path": str(path), "sha256": session.sha256}
        assert written["inputs"]["model"]["path"] is None and "not saved" in written["inputs"]["model"]["note"]
        assert "the paper's Table 2" in (out / "platform_report.md").read_text()
        assert not list(out.glob("*.tmp"))


def test_platform_page_with_a_table_matches_the_command_line(six_leg_session, cfg, size, wait_until, tmp_path, capsys):
    asyncio.run(_table(six_leg_session, cfg, size, wait_until, tmp_path, capsys))


async def _table(path, cfg, size, wait_until, tmp_path, capsys):
    model, table = tmp_path / "m.json", tmp_path / "t.csv"
    assert main(["fit", str(path), "--out", str(model)]) == 0
    assert main(["table", str(model), "--out", str(table)]) == 0
    assert main(["platform", str(table), "--recording", str(path), "--poses", "300", "--seed", "1",
                 "--out", str(tmp_path / "cli")]) == 0
    capsys.readouterr()
    cli = json.loads((tmp_path / "cli" / "platform_summary.json").read_text())
    app = StationApp(cfg, time_scale=0.0, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        # no analysis on show: the table and its recording typed in
        await run_platform(pilot, wait_until, poses=300, seed=1, compensation=table, recording=path)
        screen = app.screen
        assert screen.platform_run.summary["source"] == cli["source"]
        assert screen.platform_run.inputs["error_basis"] == cli["inputs"]["error_basis"]
        assert cli["inputs"]["error_basis"]["basis"] == "normalised"
        check_page_against(screen, cli, cli["other_measurement"])
        assert "t.csv" in str(screen.query_one("#plat-status").render())


def test_platform_page_says_what_to_do_instead_of_failing(tmp_path, cfg, size, wait_until, notes, synth_session_file):
    asyncio.run(_errors(tmp_path, cfg, size, wait_until, notes, synth_session_file))


async def _errors(tmp_path, cfg, size, wait_until, notes, synth_session_file):
    two = synth_session_file(tmp_path / "two-legs.h5", legs=(1, 2), cycles=2, step_mm=10.0)
    bad_table = tmp_path / "bad.csv"
    bad_table.write_text("leg,position_mm,error_fwd_um,error_rev_um\n1,0,zero,0\n")
    app = StationApp(cfg, time_scale=0.0, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        screen = None

        async def press_and_expect(text: str, what: str) -> None:
            count = len(notes(app))
            await pilot.press("p")
            await wait_until(pilot, lambda: len(notes(app)) > count and text in notes(app)[-1], 30, what)
            assert app.is_running and screen.platform_run is None and not screen.running
            assert "Traceback" not in notes(app)[-1] and "unexpected" not in notes(app)[-1]

        # no analysis yet
        await pilot.press("f7")
        await wait_until(pilot, lambda: app.screen.MODE == "platform", what="the Platform page")
        screen = app.screen
        await press_and_expect("Results (F3)", "the no-analysis notice")
        # a session of two legs, fitted on Results
        await open_and_fit(pilot, wait_until, two)
        await pilot.press("f7")
        await wait_until(pilot, lambda: app.screen is screen, what="the Platform page again")
        await press_and_expect("all six legs", "the six-legs notice")
        assert "legs 1-6 (Sweep, F2)" in notes(app)[-1] and "two-legs.h5" in notes(app)[-1]
        # a bad table (typed in; the recording defaults to the session on Results)
        screen.query_one("#plat-comp", Input).value = str(bad_table)
        await press_and_expect("bad.csv", "the bad-table notice")
        # a model file of two legs
        from procedures.fit import save_model

        two_model = save_model(app.analysis.model, tmp_path / "two.model.json", source_path=two,
                               source_sha256=app.analysis.session.sha256)
        screen.query_one("#plat-comp", Input).value = str(two_model)
        await press_and_expect("the model has no leg(s) [3, 4, 5, 6]", "the model-legs notice")
        # a file that is neither a table nor a model, and a bad pose count
        screen.query_one("#plat-comp", Input).value = str(two)
        await press_and_expect("give a compensation table", "the wrong-file notice")
        screen.query_one("#plat-comp", Input).value = ""
        screen.query_one("#plat-poses", Input).value = "0"
        # refused by the kind of `station platform --poses` (station.values.POSES), under the fields too
        await press_and_expect("poses: '0' is outside 1 .. 1000000", "the poses notice")
        assert "poses: '0' is outside 1 .. 1000000" in str(screen.query_one("#plat-refusal").render())
        # w before any run
        count = len(notes(app))
        await pilot.press("w")
        await wait_until(pilot, lambda: len(notes(app)) > count and "Run the experiment first" in notes(app)[-1],
                         what="the nothing-to-write notice")
