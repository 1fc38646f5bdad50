"""`station push` / `station rollback` through station.cli.main, on the simulated drive over Modbus
TCP: what the confirmation shows, the prompt, refusals that write nothing, rollback, and a link
lost in the middle of a push."""

from __future__ import annotations

import io
import json
import logging
import random
import re
import sys
from pathlib import Path

import pytest

from drivers.clock import VirtualClock
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, default_leg_configs
from drivers.sim.modbus_tcp import NoReply  # the simulated drive answers nothing
from procedures.compensation.audit import read_entries
from procedures.compensation.push import quantize, table_sha256
from procedures.compensation.table import CompTable, LegTable, table_csv_text
from station.cli import main
from station.services.wiring import open_drive
from station.services.config import StationConfig

PROFILE = DriveProfile.load()
NV = Path("runs/sim-drive-nv.json")
AUDIT = Path("runs/audit.jsonl")


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """Every command runs in a fresh directory: runs/ (audit log, simulated drive memory) is new."""
    monkeypatch.chdir(tmp_path)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def _leg_table(leg: int, scale: float = 1.0, step: float = 6.0) -> LegTable:
    n = int(round(180 / step)) + 1
    return LegTable(leg, -90.0, step, tuple(scale * (0.5 + 0.01 * i) for i in range(n)),
                    tuple(scale * (-0.25 - 0.02 * i) for i in range(n)))


def _csv(path: str, *tables: LegTable) -> str:
    Path(path).write_text(table_csv_text(CompTable({t.leg: t for t in tables})))
    return path


def station(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


class Tty(io.StringIO):
    """stdin that says it is a terminal, with the user's answer in it."""

    def isatty(self) -> bool:
        return True


def _sim_drive_state(leg: int):
    """(active bank, active table) of the simulated drive, read back from its memory file."""
    cfg = StationConfig()
    cfg.drive.url, cfg.sim.nv_path = "sim", str(NV)
    h = open_drive(cfg, leg)
    try:
        bank = h.axis.active_bank()
        return bank, h.axis.read_table(bank)
    finally:
        h.close()


def _audit(outcome: str | None = None):
    entries, problems = read_entries(AUDIT)
    assert problems == []
    return [e for e in entries if outcome is None or e.outcome == outcome]


def test_push_shows_what_it_writes_then_writes_it(capsys):
    _csv("table.csv", _leg_table(1), _leg_table(2, 2.0))
    rc, out, err = station(capsys, "push", "table.csv", "--leg", "2", "--sim", "--yes")
    assert rc == 0, err
    want = quantize(_leg_table(2, 2.0).to_bank())
    sha = table_sha256(want)
    assert "leg 2: drive StationSim LegServo-402 s/n SIM-0002 fw 1.0.0" in out
    assert "31 points, -90.000 .. +90.000 mm step 6 mm" in out
    assert f"largest correction {max(abs(v) for v in want.error_fwd_um + want.error_rev_um):.3f} um" in out
    assert f"sha256 {sha}, into bank 1 (inactive)" in out and "replaces: bank 0, empty" in out
    assert f"pushed: leg 2 bank 1 active (was bank 0); table sha256 {sha}" in out
    bank, table = _sim_drive_state(2)
    assert bank == 1 and table_sha256(table) == sha
    assert _sim_drive_state(1)[1].point_count == 0, "only the chosen leg's drive was written"
    started, ok = _audit()
    assert (started.outcome, ok.outcome, ok.leg, ok.table_sha256) == ("started", "ok", 2, sha)
    assert ok.source["path"] == "table.csv" and ok.source["leg"] == 2 and len(ok.source["sha256"]) == 64
    assert started.backup["error_fwd_um"] == [] and ok.drive.endswith("s/n SIM-0002 fw 1.0.0")


def test_without_yes_and_without_a_terminal_it_refuses(capsys, monkeypatch):
    _csv("table.csv", _leg_table(1))
    monkeypatch.setattr(sys, "stdin", io.StringIO("y\n"))  # piped input is not a confirmation
    rc, out, err = station(capsys, "push", "table.csv", "--leg", "1", "--sim")
    assert rc == 2
    assert err.count("\n") == 1 and "not confirmed: stdin is not a terminal" in err and "--yes" in err
    assert "Nothing was written" in err
    assert _sim_drive_state(1)[1].point_count == 0
    assert [e.outcome for e in _audit()] == ["refused"]


@pytest.mark.parametrize("answer, rc, written", [("n\n", 1, False), ("\n", 1, False), ("yes\n", 0, True)])
def test_the_prompt_asks_and_only_yes_writes(capsys, monkeypatch, answer, rc, written):
    _csv("table.csv", _leg_table(1))
    monkeypatch.setattr(sys, "stdin", Tty(answer))
    code, out, err = station(capsys, "push", "table.csv", "--leg", "1", "--sim")
    assert code == rc, err
    assert "Push this table to leg 1? [y/N]" in out
    assert (_sim_drive_state(1)[1].point_count == 31) == written
    assert _audit()[-1].outcome == ("ok" if written else "cancelled")
    if not written:
        assert "cancelled; nothing was written" in out


BAD = [
    # (name, CSV lines after the header, words the one-line message must contain)
    ("non-increasing", ["1,-90,0.1,0.1", "1,-84,0.1,0.1", "1,-84,0.1,0.1"],
     r"table.csv, row 4, field position_mm: -84 mm is not above the previous position"),
    ("beyond the limit", ["1,-90,0.1,0.1", "1,0,300.5,0.1", "1,90,0.1,0.1"],  # the stroke covered: a whole table
     r"table.csv, leg 1, row 3 \(\+0.0000 mm\), field error_fwd_um: 300.5 um is beyond the correction limit of the drive, \+/-300 um"),
    ("uneven", ["1,-90,0.1,0.1", "1,-84,0.1,0.1", "1,-77,0.1,0.1"],
     r"row 4, field position_mm: step 7.000000 mm differs .* resample with `station table --step`"),
    ("other leg count", [f"{leg},{x},0.1,0.1" for leg in range(1, 9) for x in (-90, 90)],
     r"the table has legs \[1, 2, 3, 4, 5, 6, 7, 8\], but this station drives legs 1-6: .*another leg count"),
    ("leg missing", ["2,-90,0.1,0.1", "2,90,0.1,0.1"], r"the table has no rows for leg 1 \(it has legs \[2\]\)"),
    ("not a table", ["\x00\x01garbage"], r"table.csv, row 2: 1 field\(s\), expected 4"),
]


@pytest.mark.parametrize("name, rows, words", BAD, ids=[b[0] for b in BAD])
def test_bad_tables_are_refused_in_one_line_and_nothing_is_written(capsys, name, rows, words):
    _csv("good.csv", _leg_table(1, 3.0))
    assert station(capsys, "push", "good.csv", "--leg", "1", "--sim", "--yes")[0] == 0
    memory = NV.read_bytes()
    Path("table.csv").write_text("leg,position_mm,error_fwd_um,error_rev_um\n" + "\n".join(rows) + "\n")
    rc, out, err = station(capsys, "push", "table.csv", "--leg", "1", "--sim", "--yes")
    # a malformed file is refused before the drive is opened; a table the drive cannot hold by the push, at the drive;
    # a hand-made file (no integrity record) read whole is said to be unverified first
    unverified = "warning: table.csv has no integrity record (made by hand, or before the station wrote one): "
    assert rc == 2 and out in ("", "drive: the SIMULATED drive (its table memory runs/sim-drive-nv.json); not a real drive\n") \
        or out.startswith(unverified) and out.count("\n") == 2, out
    assert err.startswith("station push: error: ") and err.count("\n") == 1, err
    assert re.search(words, err), err
    assert NV.read_bytes() == memory, "the drive's memory changed"
    last = _audit()[-1]
    assert (last.action, last.outcome) == ("push", "refused") and re.search(words, last.message)


def test_a_binary_file_is_refused(capsys):
    Path("table.csv").write_bytes(b"\xff\xfe\x00\x00binary")
    rc, out, err = station(capsys, "push", "table.csv", "--leg", "1", "--sim", "--yes")
    assert rc == 2 and "table.csv: not a text file" in err
    assert not NV.exists()


def test_a_leg_the_platform_does_not_have_is_refused(capsys):
    _csv("table.csv", _leg_table(1))
    rc, out, err = station(capsys, "push", "table.csv", "--leg", "7", "--sim", "--yes")
    assert rc == 2 and "--leg 7: give a leg number from 1 to 6" in err


def test_a_corrupt_model_file_makes_no_table(capsys):
    Path("model.json").write_text('{"format": "station-leg-error-model", "version": 1, "legs": {"1": ')
    rc, out, err = station(capsys, "table", "model.json", "--out", "table.csv")
    assert rc == 2 and "model.json" in err and err.count("\n") == 1
    assert not Path("table.csv").exists()


def test_rollback_restores_the_table_before_the_last_push(capsys):
    _csv("a.csv", _leg_table(3, 1.0))
    _csv("b.csv", _leg_table(3, -2.0))
    assert station(capsys, "push", "a.csv", "--leg", "3", "--sim", "--yes")[0] == 0
    assert station(capsys, "push", "b.csv", "--leg", "3", "--sim", "--yes")[0] == 0
    assert _sim_drive_state(3)[0] == 0
    rc, out, err = station(capsys, "rollback", "--leg", "3", "--sim", "--yes")
    assert rc == 0, err
    a_sha = table_sha256(quantize(_leg_table(3, 1.0).to_bank()))
    assert "rollback of the push of" in out and f"sha256 {a_sha}" in out
    bank, table = _sim_drive_state(3)
    assert bank == 1 and table_sha256(table) == a_sha
    last = _audit()[-1]
    assert (last.action, last.outcome, last.table_sha256) == ("rollback", "ok", a_sha)
    rc, out, err = station(capsys, "rollback", "--leg", "3", "--sim", "--yes")
    assert rc == 2 and "already rolled back" in err and "Nothing was written" in err


def test_rollback_without_any_push_is_refused(capsys):
    rc, out, err = station(capsys, "rollback", "--leg", "2", "--sim", "--yes")
    assert rc == 2 and "no successful push to drive StationSim LegServo-402 s/n SIM-0002" in err


@pytest.fixture
def drive_server():
    """A simulated drive server started by the test (so the test can break it), on 127.0.0.1."""
    servers = []

    def make(time_scale: float = 0.0) -> SimDriveServer:
        clock = VirtualClock(time_scale)
        plants = {i + 1: LegPlant(c, seed=i + 1) for i, c in enumerate(default_leg_configs(0, 2))}
        server = SimDriveServer(plants, clock, PROFILE)
        server.url = f"tcp://127.0.0.1:{server.start_tcp()}"
        servers.append(server)
        return server

    yield make
    for s in servers:
        s.stop()


def _client(url: str, leg: int = 1) -> ModbusServoAxis:
    return ModbusServoAxis(ModbusBus.from_url(url, timeout_s=0.5), leg, PROFILE)


def test_link_lost_at_a_random_chunk_of_a_push_leaves_the_previous_table_active(capsys, drive_server):
    server = drive_server()
    _csv("old.csv", _leg_table(1, 1.0))
    _csv("new.csv", _leg_table(1, -1.0, step=0.5))  # 361 points: 3 + 3 entry chunks, then the header
    assert station(capsys, "push", "old.csv", "--leg", "1", "--drive", server.url, "--yes")[0] == 0
    old_sha = table_sha256(quantize(_leg_table(1, 1.0).to_bank()))
    model = server._models[1]  # fault injection into the simulated drive
    seed = random.randrange(1 << 30)
    die_at = random.Random(seed).randint(1, 7)
    seen = {"n": 0}
    original = model.write

    def write(address, values):
        if PROFILE.table.bank_base[0] <= address < PROFILE.table.bank_end(0):
            seen["n"] += 1
            if seen["n"] == die_at:
                model.unresponsive = True  # the cable is pulled: no more answers
                raise NoReply("link lost")
        return original(address, values)

    model.write = write
    rc, out, err = station(capsys, "push", "new.csv", "--leg", "1", "--drive", server.url, "--yes")
    assert rc == 2 and err.count("\n") == 1, f"seed {seed}: {err}"
    assert "failed while writing bank 0" in err and "table push to bank 0 interrupted" in err, f"seed {seed}: {err}"
    assert f"previous table (bank 1, sha256 {old_sha[:12]}" in err and "is still active" in err, f"seed {seed}"
    model.unresponsive = False
    del model.write
    ax = _client(server.url)
    try:
        assert ax.active_bank() == 1 and table_sha256(ax.read_table(1)) == old_sha, f"seed {seed}, write {die_at}"
    finally:
        ax.close()
    assert [e.outcome for e in _audit()[-2:]] == ["started", "failed"]
    assert json.loads(AUDIT.read_text().splitlines()[-2])["backup"]["sha256"] == old_sha


def test_push_is_refused_while_the_axis_moves(capsys, drive_server):
    server = drive_server(time_scale=1.0)  # real time: the 60 mm move below takes 6 s
    mover = _client(server.url)
    try:
        mover.enable()
        mover.bus.write(1, PROFILE.address("controlword"), [0x1F] + PROFILE.registers["target_position"].encode(60.0))
        assert mover.status().moving
        writes = server.request_counts(1)[1]
        _csv("table.csv", _leg_table(1))
        rc, out, err = station(capsys, "push", "table.csv", "--leg", "1", "--drive", server.url, "--yes")
        assert rc == 2 and "the axis is moving" in err and "Nothing was written" in err
        assert server.request_counts(1)[1] == writes and mover.active_bank() == 0
        assert _audit()[-1].outcome == "refused"
    finally:
        mover.stop()
        mover.close()
