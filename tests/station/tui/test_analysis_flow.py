"""Results, Compensation, Diagnosis and Replay screens on a session recorded on the simulated rig.

The screens must show what the procedures compute (fit, make_table, diagnose), so the tests
compare the UI against direct calls on the same file.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest
from textual.widgets import DataTable, Input, Static

from procedures.diagnosis import diagnose
from procedures.fit import fit
from procedures.metrology.thermal import error_basis
from procedures.io.recording.reader import read_session
from procedures.compensation.table import make_table
from station.tui import capabilities
from station.tui.app import StationApp
from tests.station.tui.steps import open_session
from station.tui.widgets import XYPlot

pytestmark = pytest.mark.timeout(120)


def test_results_show_the_fit_iso_and_plots(recorded_session, cfg, size, wait_until, notes):
    asyncio.run(_results(recorded_session, cfg, size, wait_until, notes))


async def _results(path, cfg, size, wait_until, notes):
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await open_session(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        # the error of station fit and station iso230 by default: normalised to 20 degC
        points = error_basis(read_session(path))[0]
        expected = fit(points, "default")
        table = app.screen.query_one("#results-table", DataTable)
        assert table.row_count == 2
        for row, (leg, lf) in enumerate(expected.legs.items()):
            cells = table.get_row_at(row)
            assert cells[0] == str(leg) and cells[1] == str(lf.stats.n_points) and cells[2] == "3"
            assert cells[3] == f"{lf.stats.noise_floor_um:.3f}"
            assert cells[4] == f"{lf.stats.heldout_rms_um:.3f}"
        evaluate = capabilities.find("iso230")
        if evaluate is None:
            assert "ISO 230-2 evaluation not available yet" in str(app.screen.query_one("#results-status", Static).render())
        else:  # A, E, M, B, R of both directions, as procedures.reporting.iso230 computes them
            iso = evaluate(points)
            for row, leg in enumerate(expected.legs):
                shown = table.get_row_at(row)[7:12]
                want = [iso[leg].values[k] for k in "AEMBR"]
                # each cell: the value over its expanded uncertainty ("3.924\n±1.191", issue 13)
                assert [c.split("\n")[0] for c in shown] == [("n/a" if v is None else f"{v:.3f}") for v in want]
                assert all(c.split("\n")[1].startswith("±") for c in shown)
                assert all(v is not None for v in want)  # 3 cycles, same targets both ways: all computable
        # the model plot shows measured points of both directions and the two model curves
        mplot = app.screen.query_one("#model-plot", XYPlot)
        assert mplot.drawn_series == ["measured +1", "model +1", "measured −1", "model −1"]
        n_leg1 = int(np.sum(points["leg"] == 1))
        assert mplot.drawn_points == n_leg1 + 2 * 200
        assert app.screen.query_one("#residual-plot", XYPlot).drawn_points == n_leg1
        # the paper method on the same (uniformly spaced) session
        await pilot.press("m")
        await wait_until(pilot, lambda: app.analysis.method == "paper", 60, "the paper fit")
        paper = fit(points, "paper")
        assert table.get_row_at(0)[4] == f"{paper.legs[1].stats.heldout_rms_um:.3f}"
        # save the model next to the recording
        await pilot.press("w")
        await wait_until(pilot, lambda: app.analysis.model_path is not None and app.analysis.model_path.exists(),
                         what="the model file")
        assert app.analysis.model_path.name == "two-legs.paper.model.json"
        app.analysis.model_path.unlink()


def test_a_bad_session_file_is_a_notification_not_a_crash(tmp_path, cfg, size, wait_until, notes):
    asyncio.run(_bad_file(tmp_path, cfg, size, wait_until, notes))


async def _bad_file(tmp_path, cfg, size, wait_until, notes):
    bad = tmp_path / "not-a-session.h5"
    bad.write_text("hello")
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await open_session(pilot, wait_until, "f3", bad)
        await wait_until(pilot, lambda: any("not-a-session.h5" in n for n in notes(app)), 30, "the error notice")
        assert app.is_running and app.analysis is None
        status = str(app.screen.query_one("#results-status", Static).render())
        assert "not-a-session.h5" in status and "Traceback" not in status


def test_compensation_previews_the_table_against_the_drive(recorded_session, cfg, size, wait_until, notes, connected):
    asyncio.run(_compensation(recorded_session, cfg, size, wait_until, notes, connected))


async def _compensation(path, cfg, size, wait_until, notes, connected):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await open_session(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        await pilot.press("f4")
        table = app.screen.query_one("#comp-table", DataTable)
        await wait_until(pilot, lambda: table.row_count == 2 and "pts" in str(table.get_row_at(1)[6]), 30,
                         "the table and the drives' active tables")
        expected = make_table(app.analysis.model)
        for row, (leg, t) in enumerate(expected.legs.items()):
            cells = table.get_row_at(row)
            assert cells[0] == str(leg) and cells[3] == str(t.point_count)
            assert cells[2] == f"{t.step_mm:g}"
            # the simulated drives start with an empty table: the difference is the table itself
            biggest = max(np.max(np.abs(t.error_fwd_um)), np.max(np.abs(t.error_rev_um)))
            assert cells[7] == f"{biggest:.3f}"
        assert app.screen.query_one("#comp-plot", XYPlot).drawn_points == 4 * expected.legs[1].point_count
        # export
        await pilot.press("w")
        csv = path.with_name("two-legs.default.table.csv")
        await wait_until(pilot, csv.exists, what="the table CSV")
        record, header = csv.read_text().splitlines()[:2]  # the integrity record first, as `station table` writes
        assert record.startswith("# integrity: table rows=") and header == "leg,position_mm,error_fwd_um,error_rev_um"
        csv.unlink()


def test_push_after_confirming_then_verify_and_roll_back(recorded_session, cfg, size, wait_until, notes, connected):
    asyncio.run(_push(recorded_session, cfg, size, wait_until, notes, connected))


async def _push(path, cfg, size, wait_until, notes, connected):
    from procedures.compensation.audit import read_entries
    from procedures.compensation.push import quantize, table_sha256
    from procedures.compensation.verify import format_report, verify
    from station.tui.screens.common import ConfirmScreen

    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await open_session(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        await pilot.press("f4")
        comp = app.screen
        table = comp.query_one("#comp-table", DataTable)
        await wait_until(pilot, lambda: table.row_count == 2 and "pts" in str(table.get_row_at(0)[6]), 30, "the drives")
        axis = app.rig.axes[1]
        bank0 = axis.active_bank()
        empty_sha = table_sha256(axis.read_table(bank0))
        audit_path = Path(cfg.recordings_dir) / "audit.jsonl"
        # 1) cancel at the confirmation: nothing is written, the cancellation is logged
        await pilot.press("u")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the push confirmation")
        question = str(app.screen.query_one("#confirm-question").render())
        assert "leg 1" in question and axis.identity() in question  # names the leg and the drive
        await pilot.press("n")
        await wait_until(pilot, lambda: any("cancelled; nothing was written" in n for n in notes(app)), what="cancel")
        assert axis.active_bank() == bank0 and table_sha256(axis.read_table(bank0)) == empty_sha
        # 2) confirm: the table lands in the other bank, is active, and the push is audited with its backup
        await pilot.press("u")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the push confirmation")
        await pilot.press("y")
        await wait_until(pilot, lambda: any(n.startswith("pushed: leg 1 bank ") for n in notes(app)), 30, "the push")
        pushed = comp.table.legs[1]
        assert axis.active_bank() == 1 - bank0
        want_sha = table_sha256(quantize(pushed.to_bank(), app.rig.profile.table.entry_scale_um))
        assert table_sha256(axis.read_table(axis.active_bank())) == want_sha
        entries, problems = read_entries(audit_path)
        assert not problems
        assert [(e.action, e.outcome) for e in entries] == [("push", "cancelled"), ("push", "started"), ("push", "ok")]
        assert entries[-1].table_sha256 == want_sha and entries[-1].leg == 1
        # the screen now shows the drive holding the new table: no difference left
        def diff_um() -> float:
            try:
                return float(str(table.get_row_at(0)[7]))
            except ValueError:  # not read yet
                return float("inf")

        await wait_until(pilot, lambda: diff_um() <= 0.005 + 1e-9,
                         what="the drive diff to vanish (up to half the drive's 0.01 um quantum)")
        # 3) verify: the calibration's plan again on leg 1 with the table active, compared before/after
        await pilot.press("v")
        await wait_until(pilot, lambda: app.sweep.label == "verification of leg 1", what="the verification sweep")
        await wait_until(pilot, lambda: comp.verify_text != "", 60, "the verification report")
        assert app.sweep.status == "completed"
        from procedures.io.recording.reader import read_session as rs

        from procedures.compensation.verify import error_basis

        # both sessions normalised to 20 degC (the default), the report saying so first
        after_pts, before_pts, basis, _ = error_basis(rs(app.sweep.out), rs(path), True)
        expected = verify(after_pts, before_pts, [1], after_source=str(app.sweep.out), before_source=str(path))
        assert comp.verify_text == "\n".join(basis) + "\n" + format_report(expected)
        assert expected[1].after.rms_um < expected[1].before.rms_um  # the table did reduce the error
        entries, _ = read_entries(audit_path)
        assert (entries[-1].action, entries[-1].outcome, entries[-1].table_sha256) == ("verify", "completed", want_sha)
        # 4) roll back: the empty table from before the push is active again
        await pilot.press("f4")
        await wait_until(pilot, lambda: app.screen is comp, what="the Compensation screen")
        await pilot.press("b")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the rollback confirmation")
        await pilot.press("y")
        await wait_until(pilot, lambda: any(n.startswith("rolled back: leg 1 bank ") for n in notes(app)), 30, "the rollback")
        assert table_sha256(axis.read_table(axis.active_bank())) == empty_sha
        entries, _ = read_entries(audit_path)
        assert (entries[-1].action, entries[-1].outcome) == ("rollback", "ok")
        assert "rollback leg 1" in str(comp.query_one("#comp-audit", Static).render())


def test_diagnosis_opens_the_gap_report(recorded_session, cfg, size, wait_until):
    asyncio.run(_diagnosis(recorded_session, cfg, size, wait_until))


async def _diagnosis(path, cfg, size, wait_until):
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await open_session(pilot, wait_until, "f6", path)
        await wait_until(pilot, lambda: app.screen.report is not None, 90, "the diagnosis")
        expected = diagnose(read_session(path).points)
        table = app.screen.query_one("#diag-table", DataTable)
        assert table.row_count == len(expected["findings"])
        text = str(app.screen.query_one("#diag-text", Static).render())
        assert "LEG 1:" in text and "LEG 2:" in text
        plot = app.screen.query_one("#diag-plot", XYPlot)
        leg1 = expected["legs"]["1"]
        bt = leg1["by_target"]
        # the gap against position: one point per target and direction, plus the region steps
        n_gap = sum(v is not None for v in bt["gap_up_um"]) + sum(v is not None for v in bt["gap_down_um"])
        assert n_gap == 2 * len(bt["position_mm"])
        assert plot.drawn_series == ["gap +1 (up)", "gap −1 (down)", "RMS per region"]
        assert plot.drawn_points == n_gap + 2 * len(leg1["by_region"])
        await pilot.press("l")
        await wait_until(pilot, lambda: app.screen.plot_leg == "2", what="the next leg")


def test_replay_a_session_through_the_sweep_screen(recorded_session, cfg, size, wait_until, notes):
    asyncio.run(_replay(recorded_session, cfg, size, wait_until, notes))


async def _replay(path, cfg, size, wait_until, notes):
    app = StationApp(cfg, autoconnect=False, replay=path)
    async with app.run_test(size=size) as pilot:
        await wait_until(pilot, lambda: app.screen.MODE == "replay" and app.screen.session is not None, 30,
                         "the session summary")
        info = str(app.screen.query_one("#replay-info", Static).render())
        s = read_session(path)
        assert f"{len(s.points)} points on legs [1, 2]" in info and "outcome completed" in info
        assert capabilities.find("replay") is not None, "replay devices are part of this build"
        # replay as fast as possible: the same sweep screen shows it, and it matches the recording
        await pilot.press("r")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep" and app.sweep.label == "replay of two-legs.h5",
                         what="the replay on the Sweep screen")
        await wait_until(pilot, lambda: app.sweep.status == "completed" and app.sweep.note, 60, "the replay to finish")
        assert app.sweep.note == "identical to the recording"
        assert app.sweep.done == len(s.points)
        plot = app.screen.query_one("#sweep-plot", XYPlot)
        await wait_until(pilot, lambda: plot.drawn_points == int(np.sum(s.points["leg"] == 2)), what="the plot")
        replayed = read_session(app.sweep.out)
        assert replayed.attrs["rig"] == "replay" and len(replayed.points) == len(s.points)
        np.testing.assert_array_equal(replayed.points["error_um"], s.points["error_um"])
        assert app.last_session == app.sweep.out
        # the replayed session opens in Results like any other
        await pilot.press("f5")
        app.screen.query_one("#session-path", Input).value = str(path)
        await pilot.press("o")
        await wait_until(pilot, lambda: app.screen.MODE == "results" and app.analysis is not None, 60, "the fit")
        assert app.analysis.path == path


SAMPLE_FAULT = Path(__file__).resolve().parents[3] / "recordings" / "fault-beam-break.h5"


def test_replay_the_fault_cut_sample_reproduces_its_fault(cfg, size, wait_until, notes):
    asyncio.run(_replay_sample(SAMPLE_FAULT, cfg, size, wait_until, notes))


async def _replay_sample(path, cfg, size, wait_until, notes):
    original = read_session(path)
    gave_up = original.faults[original.faults["gave_up"] == 1]
    assert original.outcome == "failed" and len(gave_up) == 1
    app = StationApp(cfg, autoconnect=False, replay=path)
    async with app.run_test(size=size) as pilot:
        await wait_until(pilot, lambda: app.screen.MODE == "replay" and app.screen.session is not None, 30,
                         "the sample's summary")
        await pilot.press("r")
        await wait_until(pilot, lambda: app.sweep.status == "failed" and app.sweep.note, 90, "the replay to give up")
        assert app.sweep.note == "identical to the recording"
        last = app.sweep.faults[-1]
        assert last.gave_up and last.kind == "beam_break"
        assert (last.index, last.leg, last.run) == (int(gave_up["index"][0]), int(gave_up["leg"][0]), int(gave_up["run"][0]))
        assert app.sweep.done == len(original.points)
