"""The command line and the terminal UI give the same refusals, audit lines and figures for push,
rollback and verify on the same inputs: both run station.services.table_jobs over the simulated drive
(a real Modbus server on loopback, its table memory in a file), each in a folder of its own. And
they say the same words for how a push or rollback ended (station.services.push_jobs.outcome_lines):
what `station push` / `station rollback` print is what the Compensation page's notice shows.

The CLI is `station.cli.main` (answering its prompt through a terminal-like stdin); the UI is
the Compensation page's controller in a running app, answered through its confirmation dialog.
"""

from __future__ import annotations

import asyncio
import io
import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from procedures.compensation.audit import read_entries
from procedures.acquisition.plans import iso230_plan
from procedures.io.recording.reader import read_session
from station.cli import main
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.table_jobs import load_leg_table
from station.services.wiring import open_rig

LEG = 1
POSITIONS_MM = [-90.0 + 15.0 * i for i in range(13)]
GOOD_ROWS = [f"{LEG},{x:.6f},{0.8 + 0.01 * x:.4f},{-0.6 + 0.012 * x:.4f}" for x in POSITIONS_MM]
BAD_ROWS = list(GOOD_ROWS)
BAD_ROWS[3] = f"{LEG},{POSITIONS_MM[3]:.6f},300.5000,0.1000"  # beyond the drive's +/-300 um

# (name, table rows, operations): an operation is ("push", answer), ("rollback", answer) or ("verify", None)
CASES = [
    ("push refused: an entry beyond the drive's limit", BAD_ROWS, [("push", "y")]),
    ("push cancelled at the confirmation", GOOD_ROWS, [("push", "n")]),
    ("push", GOOD_ROWS, [("push", "y")]),
    ("rollback refused: nothing pushed yet", GOOD_ROWS, [("rollback", "y")]),
    ("push, then roll back", GOOD_ROWS, [("push", "y"), ("rollback", "y")]),
    ("verify refused: the drive's table is empty", GOOD_ROWS, [("verify", None)]),
    ("push, then verify", GOOD_ROWS, [("push", "y"), ("verify", None)]),
]


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(scope="module")
def calibration(tmp_path_factory) -> Path:
    """A small calibration of leg 1 on the simulated rig (plant seed 0): the `before` of a verify."""
    out = tmp_path_factory.mktemp("cal") / "cal.h5"
    with open_rig(StationConfig(operator="test"), legs=(LEG,), time_scale=0.0) as rig:
        assert run_sweep(rig, iso230_plan((LEG,), -80.0, 80.0, step_mm=40.0, cycles=2), out, StationConfig()).outcome \
            == "completed"
    return out


def _table_csv(folder: Path, rows: list[str]) -> Path:
    path = folder / "table.csv"
    path.write_text("leg,position_mm,error_fwd_um,error_rev_um\n" + "\n".join(rows) + "\n")
    return path


def _comparable(entries) -> list[dict]:
    """The audit entries without what differs by nature (ids, times, host, where the files are)."""
    out = []
    for e in entries:
        d = e.to_json()
        for key in ("id", "op_id", "time_utc", "host", "drive_url"):
            d.pop(key)
        details = dict(d["details"])
        for key in ("session", "session_sha256", "before_session", "push_time_utc", "rolls_back"):  # files differ by ids and times
            details.pop(key, None)
        d["details"] = json.loads(json.dumps(details).replace(str(Path.cwd()), ""))
        if d["source"]:
            d["source"] = {k: (Path(v).name if k == "path" else v) for k, v in d["source"].items()}
        d["backup"] = d["backup"]["sha256"] if d["backup"] else None
        d["message"] = d["message"].replace(str(Path.cwd()) + "/", "")
        out.append(d)
    return out


def _said(folder: Path, text: str) -> list[str]:
    """The lines of `text` without the folder each front end works in (the audit log's path)."""
    return [line for line in text.replace(f"{folder}/", "").splitlines() if line.strip()]


def _run_cli(folder: Path, csv: Path, operations, calibration: Path, monkeypatch, capsys) -> tuple[list, list]:
    """The audit entries, and for each push or rollback (exit code, what it printed: stdout, then
    its error line without the `station CMD: error: ` prefix)."""
    monkeypatch.chdir(folder)
    said = []
    for n, (op, answer) in enumerate(operations):
        capsys.readouterr()
        if op == "push":
            monkeypatch.setattr("sys.stdin", Tty(answer + "\n"))
            code = main(["push", csv.name, "--leg", str(LEG), "--sim"])
        elif op == "rollback":
            monkeypatch.setattr("sys.stdin", Tty(answer + "\n"))
            code = main(["rollback", "--leg", str(LEG), "--sim"])
        else:  # the UI's simulated rig repeats the plant's noise: the same seeds here
            main(["verify", "--leg", str(LEG), "--sim", "--before", str(calibration), "--out", f"verify-{n}.h5",
                  "--seed", "0", "--noise-seed", "0"])
            continue
        out, err = capsys.readouterr()
        out = out.replace("[y/N] ", "[y/N]\n")  # at a terminal, the answer typed ends the prompt's line
        said.append((code, _said(folder, out) + [line.removeprefix(f"station {op}: error: ")
                                                 for line in _said(folder, err)]))
    return read_entries(folder / "runs" / "audit.jsonl")[0], said


async def _run_tui(folder: Path, csv: Path, operations, calibration: Path) -> tuple[list, list]:
    """The audit entries, and for each push or rollback the (text, severity) of the page's notice."""
    from station.tui.app import StationApp
    from station.tui.screens.common import ConfirmScreen

    cfg = StationConfig()  # the same operator as the CLI's: the login name
    cfg.recordings_dir = str(folder / "runs")
    cfg.with_sim_memory()
    audit = folder / "runs" / "audit.jsonl"
    # no Rig-page status polls: each reads the simulated interferometer, which draws its noise
    # from the plant's random stream, so the verification's noise would depend on how many
    # polls the UI happened to make (the CLI makes none). The Rig page polls only while shown:
    # connect from the Compensation page.
    app = StationApp(cfg, time_scale=0.0, legs=(LEG,), autoconnect=False)

    async def wait(pilot, condition, what: str, timeout_s: float = 60.0) -> None:
        for _ in range(int(timeout_s / 0.02)):
            if condition():
                return
            await pilot.pause(0.02)
        raise AssertionError(f"timed out waiting for {what}")

    def count() -> int:
        return len(read_entries(audit)[0])

    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("f4")
        comp = app.screen
        notices = []
        shown = comp.jobs.notice

        def notice(message):  # what the page shows of how a push or rollback ended
            notices.append(shown(message))
            return notices[-1]

        comp.jobs.notice = notice
        app.connect_rig()
        await wait(pilot, lambda: app.rig is not None, "the rig")
        for op, answer in operations:
            before = count()
            if op == "push":
                table, source = load_leg_table(csv.name, LEG)
                comp.jobs.push(LEG, table, source)
            elif op == "rollback":
                comp.jobs.rollback(LEG)
            else:
                assert comp.jobs.verify(LEG, SimpleNamespace(session=read_session(calibration)))
            if answer is not None:
                await wait(pilot, lambda: isinstance(app.screen, ConfirmScreen) or count() > before, "the confirmation")
                if isinstance(app.screen, ConfirmScreen):
                    await pilot.press(answer)
            final = {"push": ("ok", "refused", "cancelled", "failed"), "rollback": ("ok", "refused", "cancelled", "failed"),
                     "verify": ("refused", "completed", "aborted", "failed")}[op]
            await wait(pilot, lambda: count() > before and read_entries(audit)[0][-1].outcome in final
                       and not app.sweep.active, f"the end of the {op}")
            if op != "verify":
                await wait(pilot, lambda: len(notices) == sum(o != "verify" for o, _ in operations[:operations.index((op, answer)) + 1]),
                           f"the notice of the {op}")
            await pilot.pause(0.1)
    return read_entries(audit)[0], [(text, severity) for text, severity in notices]


@pytest.mark.parametrize("name, rows, operations", CASES, ids=[c[0] for c in CASES])
def test_cli_and_tui_log_the_same_refusals_outcomes_and_figures(name, rows, operations, calibration, tmp_path,
                                                                monkeypatch, capsys):
    cli_dir, tui_dir = tmp_path / "cli", tmp_path / "tui"
    cli_dir.mkdir()
    tui_dir.mkdir()
    cli, cli_said = _run_cli(cli_dir, _table_csv(cli_dir, rows), operations, calibration, monkeypatch, capsys)
    monkeypatch.chdir(tui_dir)
    tui, tui_said = asyncio.run(_run_tui(tui_dir, _table_csv(tui_dir, rows), operations, calibration))
    assert cli, "the CLI logged nothing"
    a, b = _comparable(cli), _comparable(tui)
    assert len(a) == len(b), (a, b)
    for i, (x, y) in enumerate(zip(a, b)):
        assert x == y, (i, _diff(x, y))
    # every operation ended as the case says, the same way in both
    finals = [e.outcome for e in cli if e.outcome != "started"]
    assert len(finals) == len(operations)
    if "refused" in name:
        assert finals[-1] == "refused"
    if "verify" in name and "refused" not in name:
        assert finals[-1] in ("completed",) and cli[-1].details["ratio"] == tui[-1].details["ratio"]
    # and both said the same words for how each push or rollback ended: the page's notice is
    # lines the command printed, together, and an error there is an error here
    tables = [op for op, _ in operations if op != "verify"]
    assert len(cli_said) == len(tui_said) == len(tables), (cli_said, tui_said)
    for op, final, (code, printed), (text, severity) in zip(tables, [e for e in cli if e.outcome != "started"
                                                                      and e.action != "verify"], cli_said, tui_said):
        notice = _said(tui_dir, text)
        assert notice and any(printed[i:i + len(notice)] == notice for i in range(len(printed))), (op, notice, printed)
        assert (code, severity) == {"ok": (0, "information"), "cancelled": (1, "information"),
                                    "refused": (2, "error")}[final.outcome], (op, final.outcome, code, severity)
        first = {"ok": "pushed: leg 1 bank " if op == "push" else "rolled back: leg 1 bank ",
                 "cancelled": "cancelled; nothing was written", "refused": final.message}[final.outcome]
        assert notice[0].startswith(first), (op, notice)



def _diff(a, b, path: str = "") -> list[str]:
    """Where two JSON-like values differ, as 'path: a != b' lines."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b)) for d in _diff(a.get(k), b.get(k), f"{path}.{k}")]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]
