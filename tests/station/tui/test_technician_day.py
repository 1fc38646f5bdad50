"""Issue 17, "A technician's day", on the analysis pages: the session list of a picker, the
faults of a recorded and a replayed session on Replay, the report and CSV of Results (the same
files as `station report` and `station export`), the twin of Diagnosis (the choices of `station
diagnose --twin`), Results' error line following the method on show, and damaged files.
"""

from __future__ import annotations

import asyncio
import shutil
import time
from pathlib import Path

import pytest
from textual.widgets import DataTable, Input, Select, Static

from procedures.io.recording.reader import read_session
from station.tui.app import StationApp

pytestmark = pytest.mark.timeout(180)

REPO = Path(__file__).resolve().parents[3]
SAMPLE_FAULT = REPO / "recordings" / "fault-beam-break.h5"
SAMPLE_6LEGS = REPO / "recordings" / "calibration-6legs.h5"


def status_text(app, selector: str) -> str:
    return str(app.screen.query_one(selector, Static).render())


# -- 1. the session list of a picker ----------------------------------------------------------------

def test_choosing_from_the_list_then_open_keeps_the_path(recorded_session, cfg, size, wait_until, notes):
    """Textual 8.2: Select.BLANK is False. A session chosen from the list, opened, then the list
    rescanned (every new session does it) used to put 'Select.NULL' in the path field, and Open
    again opened a file named 'Select.NULL'."""
    asyncio.run(_choose_then_open(recorded_session, cfg, size, wait_until, notes))


async def _choose_then_open(path, cfg, size, wait_until, notes):
    runs = Path(cfg.recordings_dir)
    runs.mkdir(parents=True)
    mine = runs / path.name
    shutil.copy(path, mine)
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f5")
        await wait_until(pilot, lambda: app.screen.MODE == "replay", what="the Replay page")
        replay = app.screen
        listed = replay.query_one("#session-list", Select)
        await wait_until(pilot, lambda: str(mine) in [str(v) for _, v in listed._options], what="the session list")
        listed.value = str(mine)
        field = replay.query_one("#session-path", Input)
        await wait_until(pilot, lambda: field.value == str(mine), what="the path field to take the choice")
        await pilot.click("#session-open")
        await wait_until(pilot, lambda: replay.session_path == mine, 30, "the session")
        # the new session rescans the list (nothing chosen in it any more), whose Changed(Select.NULL)
        # goes from the list to its picker: two message hops, each handled by the time a pause ends
        await wait_until(pilot, lambda: listed.value is Select.NULL, what="the list rescanned after the new session")
        await pilot.pause()
        await pilot.pause()
        assert field.value == str(mine)
        assert listed.value is Select.NULL  # the list was rescanned: nothing chosen in it any more
        replay.session = None
        # a Button ignores a press while it still shows the last one ("-active", 0.2 s): without the
        # fixed pause before, a fast machine would click into nothing
        opener = replay.query_one("#session-open")
        await wait_until(pilot, lambda: not opener.has_class("-active"), what="Open's last press to end")
        await pilot.click("#session-open")  # Open again: the same file
        await wait_until(pilot, lambda: replay.session is not None, 30, "the session read again")
        assert replay.session_path == mine
        assert not any("Select.NULL" in n for n in notes(app))


# -- 2. the faults of a recorded session, and of its replay, on the Replay page ----------------------

def test_replay_page_lists_the_recorded_and_the_replayed_faults(cfg, size, wait_until, notes):
    asyncio.run(_faults(SAMPLE_FAULT, cfg, size, wait_until, notes))


def expected_rows(faults, session: str) -> list[list[str]]:
    return [[session, str(int(f["index"])), str(int(f["leg"])), str(int(f["run"])), f"{float(f['target_mm']):+.4f}",
             f"{float(f['time_s']):.3f}", f["kind"].decode(), str(int(f["attempt"])), "yes" if f["gave_up"] else "no",
             f["message"].decode()] for f in faults]


async def _faults(path, cfg, size, wait_until, notes):
    recorded = read_session(path)
    assert len(recorded.faults) == 4
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f5")
        await wait_until(pilot, lambda: app.screen.MODE == "replay", what="the Replay page")
        replay = app.screen
        replay.query_one("#session-path", Input).value = str(path)
        await pilot.click("#session-open")
        table = replay.query_one("#replay-faults", DataTable)
        await wait_until(pilot, lambda: replay.session is not None and table.row_count == 4, 30, "the fault list")
        rows = [list(map(str, table.get_row_at(i))) for i in range(table.row_count)]
        assert rows == expected_rows(recorded.faults, "recorded")
        assert [r[8] for r in rows] == ["no", "no", "no", "yes"]  # three retries, then given up
        # replay it: back on Replay, the replayed run's faults are listed under the recorded ones
        await pilot.press("r")
        await wait_until(pilot, lambda: app.sweep.status == "failed" and app.sweep.note, 90, "the replay to give up")
        await pilot.press("f5")
        replayed = read_session(app.sweep.out)
        await wait_until(pilot, lambda: table.row_count == 4 + len(replayed.faults), 30, "the replayed faults")
        rows = [list(map(str, table.get_row_at(i))) for i in range(table.row_count)]
        assert rows == expected_rows(recorded.faults, "recorded") + expected_rows(replayed.faults, "replayed")
        # the replay gave up at the same point, for the same reason
        assert [r[1:4] + r[6:9] for r in rows[4:]][-1] == [r[1:4] + r[6:9] for r in rows[:4]][-1]
        info = status_text(app, "#replay-info")
        assert f"replayed as {app.sweep.out.name}" in info and "outcome failed" in info
        # another session on show: its own faults only
        replay.query_one("#session-path", Input).value = str(SAMPLE_6LEGS)
        await pilot.click("#session-open")
        six = read_session(SAMPLE_6LEGS)
        await wait_until(pilot, lambda: replay.session_path == SAMPLE_6LEGS, 30, "the other session")
        assert table.row_count == len(six.faults)


# -- 3. report and CSV from the Results page: the files of `station report` and `station export` -----

async def open_on(pilot, wait_until, key: str, path) -> None:
    app = pilot.app
    await pilot.press(key)
    await wait_until(pilot, lambda: app.screen.query("#session-path"), what="the session picker")
    app.screen.query_one("#session-path", Input).value = str(path)
    await pilot.click("#session-open")


def test_results_writes_the_report_and_csv_of_the_cli(recorded_session, cfg, size, wait_until, notes, tmp_path):
    session = tmp_path / "day" / "two-legs.h5"
    session.parent.mkdir()
    shutil.copy(recorded_session, session)
    asyncio.run(_report_and_csv(session, cfg, size, wait_until, notes, tmp_path / "cli"))


async def _report_and_csv(path, cfg, size, wait_until, notes, cli_dir):
    from station.cli import main

    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await open_on(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        # r: the report of the model on show, the default model of `station fit` (normalised to 20 degC
        # by default): `station report FILE --out DIR --model MODEL.json` with that model
        await pilot.press("r")
        out = path.parent / "report" / "two-legs.default"
        await wait_until(pilot, lambda: any("Report written to" in n for n in notes(app)), 60, "the report")
        note = next(n for n in notes(app) if "Report written to" in n)
        assert str(out) in note and "summary.md" in note
        cli_dir.mkdir()
        assert main(["fit", str(path), "--out", str(cli_dir / "default.model.json")]) == 0
        assert main(["report", str(path), "--out", str(cli_dir / "report"),
                     "--model", str(cli_dir / "default.model.json")]) == 0
        for name in ("errors.png", "residuals.png", "histograms.png", "spectrum.png"):
            assert (out / name).stat().st_size > 0
        for name in ("summary.json", "summary.md"):
            assert (out / name).read_text() == (cli_dir / "report" / name).read_text(), name
        # on the raw error (t) the model on show is the one `station report FILE --raw` fits itself
        shutil.rmtree(out)
        await pilot.press("t")
        await wait_until(pilot, lambda: app.analysis.raw, 60, "the fit on the raw error")
        app.clear_notifications()
        await pilot.press("r")
        await wait_until(pilot, lambda: any("Report written to" in n for n in notes(app)), 60, "the raw report")
        assert main(["report", str(path), "--out", str(cli_dir / "report-raw"), "--raw"]) == 0
        for name in ("summary.json", "summary.md"):
            assert (out / name).read_text() == (cli_dir / "report-raw" / name).read_text(), name
        assert (out / "summary.json").read_text() != (cli_dir / "report" / "summary.json").read_text()
        # again: refused, nothing replaced
        app.clear_notifications()
        before = (out / "summary.json").stat().st_mtime_ns
        await pilot.press("r")
        await wait_until(pilot, lambda: any("exists already" in n for n in notes(app)), 10, "the refusal")
        assert str(out) in notes(app)[-1] and "rename or delete it" in notes(app)[-1]
        assert (out / "summary.json").stat().st_mtime_ns == before
        # e: the CSV of `station export FILE --out FILE.csv`
        await pilot.press("e")
        csv = path.with_suffix(".csv")
        await wait_until(pilot, lambda: any("exported" in n for n in notes(app)), 30, "the CSV")
        assert f"to {csv}" in next(n for n in notes(app) if "exported" in n)
        assert main(["export", str(path), "--out", str(cli_dir / "x.csv")]) == 0
        assert csv.read_bytes() == (cli_dir / "x.csv").read_bytes()
        app.clear_notifications()
        csv.write_text("keep me")
        await pilot.press("e")
        await wait_until(pilot, lambda: any("exists already" in n for n in notes(app)), 10, "the refusal")
        assert str(csv) in notes(app)[-1] and csv.read_text() == "keep me"
        # the paper model on show: as `station report --model` its saved file
        await pilot.press("m")
        await wait_until(pilot, lambda: app.analysis.method == "paper", 60, "the paper fit")
        await pilot.press("w")
        await wait_until(pilot, lambda: app.analysis.model_path is not None, 10, "the saved model")
        await pilot.press("r")
        paper = path.parent / "report" / "two-legs.paper"
        await wait_until(pilot, lambda: any(f"{paper}" in n for n in notes(app)), 60, "the paper report")
        assert main(["report", str(path), "--out", str(cli_dir / "paper"), "--model", str(app.analysis.model_path)]) == 0
        for name in ("summary.json", "summary.md"):
            assert (paper / name).read_text() == (cli_dir / "paper" / name).read_text(), name


def test_results_report_needs_a_session(cfg, size, wait_until, notes):
    asyncio.run(_no_session(cfg, size, wait_until, notes))


async def _no_session(cfg, size, wait_until, notes):
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f3")
        await wait_until(pilot, lambda: app.screen.MODE == "results", what="Results")
        await pilot.press("r")
        await pilot.press("e")
        await wait_until(pilot, lambda: len(notes(app)) == 2, 5, "two notices")
        assert all("Open a session first" in n for n in notes(app))


# -- 5. Results: the error line belongs to the method on show ------------------------------------------

@pytest.fixture
def irregular_session(tmp_path):
    """Legs 1 and 2 on ISO 230-2 irregular targets: the paper's method refuses them."""
    from drivers.plant.leg import default_leg_configs
    from procedures.acquisition.plans import irregular_targets
    from procedures.synthetic import synth_session
    from tests.tooling import write_points_session

    cfgs = default_leg_configs(seed=0)
    points = synth_session({1: cfgs[0], 2: cfgs[1]}, irregular_targets(-90.0, 90.0, 21, 0), cycles=3, seed=0)
    folder = tmp_path / "irregular"
    folder.mkdir()
    return write_points_session(folder / "irregular.h5", points)


def test_results_drops_the_paper_error_when_switching_back(irregular_session, cfg, size, wait_until, notes,
                                                          monkeypatch):
    import procedures.fit

    real_fit = procedures.fit.fit
    slow = {"paper": 0.0, "answered": []}

    def fit(points, method="default", **kwargs):  # the paper fit takes its time when asked to
        time.sleep(slow.get(method, 0.0))
        try:
            return real_fit(points, method, **kwargs)
        finally:
            slow["answered"].append(method)

    monkeypatch.setattr(procedures.fit, "fit", fit)
    asyncio.run(_stale_error(irregular_session, cfg, size, wait_until, notes, slow))


async def _stale_error(path, cfg, size, wait_until, notes, slow):
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await open_on(pilot, wait_until, "f3", path)
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the default fit")
        screen = app.screen
        table = screen.query_one("#results-table", DataTable)
        assert table.row_count == 2
        # m: the paper's method, which refuses irregular targets
        await pilot.press("m")
        await wait_until(pilot, lambda: any("uniformly spaced" in n for n in notes(app)), 60, "the paper error")
        status = status_text(app, "#results-status")
        assert "uniformly spaced" in status and "the table shows the default model" in status
        assert app.analysis.method == "default" and table.row_count == 2
        # m again: back to default, on show already; the paper's error goes
        await pilot.press("m")
        await wait_until(pilot, lambda: "uniformly spaced" not in status_text(app, "#results-status"), 5,
                         "the error line to go")
        status = status_text(app, "#results-status")
        assert "method default" in status and table.row_count == 2
        assert screen.query_one("#method", Select).value == "default"
        # m, and m again while the paper fit is under way: its answer is dropped, its error never shows
        app.clear_notifications()
        slow["paper"] = 1.5
        answered = len(slow["answered"])  # the fits asked for so far have all answered
        await pilot.press("m")
        await wait_until(pilot, lambda: screen._fitting is not None and screen._fitting[1] == "paper", 5,
                         "the paper fit to start")
        await pilot.press("m")
        await wait_until(pilot, lambda: screen._fitting is None, 60, "the default fit")
        # the paper fit's answer (its error) has come back and been handled: a fixed pause let this
        # pass unchecked when a loaded machine took longer than the pause for the 1.5 s fit
        await wait_until(pilot, lambda: "paper" in slow["answered"][answered:], 60, "the paper fit's answer")
        await pilot.pause()
        await pilot.pause()
        assert "uniformly spaced" not in status_text(app, "#results-status")
        assert not any("uniformly spaced" in n for n in notes(app))
        assert app.analysis.method == "default" and screen.query_one("#method", Select).value == "default"


# -- 4. the twin of the Diagnosis page: the choices of `station diagnose --twin` ------------------------

def test_diagnosis_twin_choices_give_the_cli_report(recorded_session, cfg, size, wait_until, notes, tmp_path):
    from procedures.fit import fit, save_model

    session = tmp_path / "day" / "two-legs.h5"
    session.parent.mkdir()
    shutil.copy(recorded_session, session)
    s = read_session(session)
    model = save_model(fit(s.points, "paper"), tmp_path / "day" / "two-legs.paper.model.json",
                       source_path=session, source_sha256=s.sha256)
    asyncio.run(_twins(session, model, cfg, size, wait_until, notes, tmp_path / "cli"))


async def _twins(path, model, cfg, size, wait_until, notes, cli_dir):
    import json

    from procedures.diagnosis import to_json
    from station.cli import main

    cli_dir.mkdir()
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f6")
        await wait_until(pilot, lambda: app.screen.MODE == "diagnosis", what="the Diagnosis page")
        screen = app.screen
        twin = screen.query_one("#twin", Select)
        assert twin.value == "fitted"  # the command's default: no --twin, the twin fitted on the recording
        spec = screen.query_one("#twin-spec", Input)
        screen.query_one("#session-path", Input).value = str(path)

        async def diagnose_with(kind: str, cli_args: list[str]) -> None:
            screen.report = None
            twin.value = kind
            await pilot.pause()
            await pilot.press("d")
            await wait_until(pilot, lambda: screen.report is not None, 90, f"the diagnosis with twin {kind}")
            out = cli_dir / f"{kind}-{len(cli_args)}.json"
            assert main(["diagnose", str(path), *cli_args, "--json", str(out)]) == 0
            assert json.loads(to_json(screen.report)) == json.loads(out.read_text()), kind

        await diagnose_with("fitted", [])
        await diagnose_with("sim", ["--twin", "sim:default"])
        assert "simulated plant (default)" in status_text(app, "#diag-status")
        spec.value = str(model)  # typing a twin chooses "file"
        await wait_until(pilot, lambda: twin.value == "file", 5, "the file choice")
        await diagnose_with("file", ["--twin", str(model)])
        spec.value = str(path)  # a reference recording
        await diagnose_with("file", ["--twin", str(path), "--alpha", "0.001"])
        # a file that is not there: said in a notification, as the command says it
        spec.value = str(path.with_name("none.json"))
        await pilot.press("d")
        await wait_until(pilot, lambda: any("none.json: no such file" in n for n in notes(app)), 10, "the refusal")
        assert "none.json" in status_text(app, "#diag-status")
        # "file" with nothing typed: asks for it
        spec.value = ""
        twin.value = "file"
        app.clear_notifications()
        await pilot.pause()
        await pilot.press("d")
        await wait_until(pilot, lambda: any("Type the twin" in n for n in notes(app)), 5, "the question")


# -- 6. a damaged session file on Results, Replay and Diagnosis ------------------------------------------

@pytest.mark.parametrize("percent", [10, 50])
def test_a_cut_session_file_is_a_notice_on_every_page_and_the_ui_stays_live(percent, tmp_path, cfg, size,
                                                                            wait_until, notes, monkeypatch):
    import threading

    import procedures.io.recording.reader as reader

    data = SAMPLE_6LEGS.read_bytes()
    cut = tmp_path / "cut" / f"calibration-6legs-{percent}.h5"
    cut.parent.mkdir()
    cut.write_bytes(data[: len(data) * percent // 100])
    real_read = reader.read_session
    threads: list[threading.Thread] = []

    def read_session(path, *args, **kwargs):  # where the pages read sessions
        threads.append(threading.current_thread())
        return real_read(path, *args, **kwargs)

    monkeypatch.setattr(reader, "read_session", read_session)
    asyncio.run(_cut_file(cut, cfg, size, wait_until, notes, threads))


async def _cut_file(cut, cfg, size, wait_until, notes, threads):
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        ui = threading_current()
        for key, page, status in (("f3", "Results", "#results-status"), ("f5", "Replay", "#replay-info"),
                                  ("f6", "Diagnosis", "#diag-status")):
            app.clear_notifications()
            await open_on(pilot, wait_until, key, cut)
            t0 = time.monotonic()
            await wait_until(pilot, lambda: any(cut.name in n for n in notes(app)), 5.0, f"the notice on {page}")
            assert time.monotonic() - t0 < 5.0
            notice = next(n for n in notes(app) if cut.name in n)
            assert str(cut) in notice and "cut short" in notice and "copy it again" in notice, notice
            assert "Traceback" not in notice
            assert "cut short" in status_text(app, status)
        assert threads and all(t is not ui for t in threads), "a page read a session on the UI thread"
        assert app.analysis is None and app.last_session is None
        # still live: another page, a key that reacts
        await pilot.press("f3")
        await wait_until(pilot, lambda: app.screen.MODE == "results", 5, "the Results page")
        method = app.screen.query_one("#method", Select)
        assert method.value == "default"
        await pilot.press("m")
        await wait_until(pilot, lambda: method.value == "paper", 5, "m to switch the method")
        await pilot.press("f5")
        await wait_until(pilot, lambda: app.screen.MODE == "replay", 5, "the Replay page")
        assert app.screen.session is None and app.screen.query_one("#replay-faults", DataTable).row_count == 0
        app.clear_notifications()
        await pilot.press("o")
        await wait_until(pilot, lambda: any("Choose a session first" in n for n in notes(app)), 5, "o to answer")


def threading_current():
    import threading

    return threading.current_thread()
