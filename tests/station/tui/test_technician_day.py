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

from procedures.recording.reader import read_session
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
        await pilot.pause(0.2)  # the rescan after the new session has posted its Changed(Select.NULL)
        assert field.value == str(mine)
        assert listed.value is Select.NULL  # the list was rescanned: nothing chosen in it any more
        replay.session = None
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
