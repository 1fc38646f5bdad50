"""One confirmed push of every leg (a whole platform after its calibration), from the command
line (`station push TABLE.csv --leg all`) and from the terminal UI (Compensation page, `U`).

Every leg is checked before anything is written: one bad leg refuses the whole push.
"""

from __future__ import annotations

import asyncio
import io
from pathlib import Path


from procedures.compensation.audit import read_entries
from station.cli import main
from station.services.config import StationConfig
from station.services.wiring import open_drive

LEGS = (1, 2, 3, 4, 5, 6)


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def _table(path: Path, bad_leg: int | None = None) -> Path:
    rows = []
    for leg in LEGS:
        for i in range(7):
            fwd = 400.0 if (leg == bad_leg and i == 3) else 0.1 * leg + 0.01 * i
            rows.append(f"{leg},{-90 + 30 * i:.6f},{fwd:.4f},{-0.05 * leg:.4f}")
    path.write_text("leg,position_mm,error_fwd_um,error_rev_um\n" + "\n".join(rows) + "\n")
    return path


def _active_banks(nv: Path) -> dict[int, int]:
    cfg = StationConfig()
    cfg.drive.url, cfg.sim.nv_path = "sim", str(nv)
    with open_drive(cfg, LEGS) as drive:
        return {leg: axis.active_bank() for leg, axis in drive.axes.items()}


def test_cli_pushes_every_leg_after_one_confirmation(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _table(Path("t.csv"))
    monkeypatch.setattr("sys.stdin", Tty("y\n"))
    assert main(["push", "t.csv", "--leg", "all", "--sim"]) == 0
    out = capsys.readouterr().out
    assert out.count("[y/N]") == 1 and "Push these tables to legs 1, 2, 3, 4, 5, 6?" in out
    # the words the Compensation page's notice shows too (station.services.push_jobs.outcome_lines)
    assert "pushed legs [1, 2, 3, 4, 5, 6]: each has its new table active\n" in out
    assert out.count("pushed: leg ") == 6 and "backup of the previous table(s) is in runs/audit.jsonl\n" in out
    assert _active_banks(Path("runs/sim-drive-nv.json")) == {leg: 1 for leg in LEGS}
    entries = read_entries(Path("runs/audit.jsonl"))[0]
    assert [(e.leg, e.outcome) for e in entries] == [(leg, o) for leg in LEGS for o in ("started", "ok")]


def test_cli_cancel_writes_nothing_and_logs_each_leg(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _table(Path("t.csv"))
    monkeypatch.setattr("sys.stdin", Tty("n\n"))
    assert main(["push", "t.csv", "--leg", "1-6", "--sim"]) == 1
    assert _active_banks(Path("runs/sim-drive-nv.json")) == {leg: 0 for leg in LEGS}
    assert [(e.leg, e.outcome) for e in read_entries(Path("runs/audit.jsonl"))[0]] == [(leg, "cancelled") for leg in LEGS]


def test_one_leg_the_drive_cannot_hold_refuses_the_whole_push(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _table(Path("t.csv"), bad_leg=4)
    assert main(["push", "t.csv", "--leg", "all", "--sim", "--yes"]) == 2
    err = capsys.readouterr().err
    assert "leg 4" in err and "400 um is beyond the correction limit" in err and "nothing was written to any leg" in err
    assert _active_banks(Path("runs/sim-drive-nv.json")) == {leg: 0 for leg in LEGS}
    assert [(e.leg, e.outcome) for e in read_entries(Path("runs/audit.jsonl"))[0]] == [(4, "refused")]


def test_the_ui_pushes_every_leg_after_one_confirmation(tmp_path):
    asyncio.run(_ui_push_all(tmp_path))


async def _ui_push_all(tmp_path):
    from procedures.compensation.table import read_table_csv
    from station.tui.app import StationApp
    from station.tui.screens.common import ConfirmScreen

    cfg = StationConfig()
    cfg.recordings_dir = str(tmp_path / "runs")
    cfg.with_sim_memory()
    app = StationApp(cfg, time_scale=0.0)

    async def wait(pilot, condition, what: str) -> None:
        for _ in range(3000):
            if condition():
                return
            await pilot.pause(0.02)
        raise AssertionError(f"timed out waiting for {what}")

    async with app.run_test(size=(120, 40)) as pilot:
        await wait(pilot, lambda: app.rig is not None, "the rig")
        await pilot.press("f4")
        comp = app.screen
        comp.table = read_table_csv(_table(tmp_path / "t.csv"))  # as if made from a model (t)
        await pilot.press("U")
        # the dialog and its contents: a dialog is pushed before its widgets are mounted
        await wait(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"),
                   "the confirmation")
        question = str(app.screen.query_one("#confirm-question").render())
        assert all(f"leg {leg}: drive" in question for leg in LEGS)
        await pilot.press("y")
        audit = Path(cfg.recordings_dir) / "audit.jsonl"
        await wait(pilot, lambda: audit.exists() and len(read_entries(audit)[0]) == 12, "every leg's push")
        await wait(pilot, lambda: any("pushed legs [1, 2, 3, 4, 5, 6]" in n.message for n in app._notifications),
                   "the notice")
        assert {leg: axis.active_bank() for leg, axis in app.rig.axes.items()} == {leg: 1 for leg in LEGS}


def test_closing_the_ui_while_a_push_awaits_its_confirmation_writes_nothing(tmp_path):
    """Nobody can answer any more: the push is cancelled (and logged so), the drive untouched."""
    asyncio.run(_close_during_confirmation(tmp_path))


async def _close_during_confirmation(tmp_path):
    from procedures.compensation.table import read_table_csv
    from station.tui.app import StationApp
    from station.tui.screens.common import ConfirmScreen

    cfg = StationConfig()
    cfg.recordings_dir = str(tmp_path / "runs")
    cfg.with_sim_memory()
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=(120, 40)) as pilot:
        for _ in range(3000):
            if app.rig is not None:
                break
            await pilot.pause(0.02)
        await pilot.press("f4")
        app.screen.table = read_table_csv(_table(tmp_path / "t.csv"))
        await pilot.press("u")
        for _ in range(3000):
            if isinstance(app.screen, ConfirmScreen):
                break
            await pilot.pause(0.02)
        assert isinstance(app.screen, ConfirmScreen)
        app.exit()
    audit = Path(cfg.recordings_dir) / "audit.jsonl"
    for _ in range(100):  # the worker notices within its 0.2 s wait
        if audit.exists() and read_entries(audit)[0]:
            break
        await asyncio.sleep(0.05)
    assert [(e.leg, e.outcome) for e in read_entries(audit)[0]] == [(1, "cancelled")]
    assert _active_banks(Path(cfg.sim.nv_path)) == {leg: 0 for leg in LEGS}
