"""Files that prove themselves (issue 31, item 2).

A table CSV cut or edited is refused by `station push` against the simulated drive (a real Modbus
server on 127.0.0.1) with the drive's tables unchanged: both banks' contents, the active bank and
the drive's write counter, read before and after. Every cut position of a table file, and
generated single-byte edits, are refused or read whole, never as a shorter table. Models and
serials lists likewise; `station table` refuses a step or range beyond the stroke and, unless
accepted, a model that made a leg worse on held-out data.

Budgets: the reader-level sweeps over every cut are pure and take about a second; the pushes
through the CLI and the drive take ~0.1 s each, so their hypothesis test runs 10 examples here and
200 with HYPOTHESIS_PROFILE=long.
"""

from __future__ import annotations

import dataclasses
import io
import json
import logging
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.clock import VirtualClock
from drivers.errors import TableRefused
from drivers.interfaces import DriveLimits
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, default_leg_configs
from procedures.compensation.push import quantize, table_sha256
from procedures.compensation.table import CompTable, LegTable, check_covers_stroke, table_csv_text
from procedures.vocabulary import InputError
from procedures.fit import fit, load_model, save_model
from procedures.io.integrity import UNVERIFIED, VERIFIED
from station.cli import main
from station.services.serials import read_serials_file_checked, write_serials_file
from procedures.synthetic import synth_session
from station.services.table_jobs import load_leg_table

LONG = os.environ.get("HYPOTHESIS_PROFILE") == "long"
PROFILE = DriveProfile.load()
SOFT = DriveLimits(-95.0, 95.0, 20.0, 200.0)  # drivers/modbus/profiles/default.toml [limits]


def _leg(leg: int, scale: float, step: float = 6.0) -> LegTable:
    n = int(round(180 / step)) + 1
    return LegTable(leg, -90.0, step, tuple(scale * (0.5 + 0.0123 * i) for i in range(n)),
                    tuple(scale * (-0.25 - 0.0211 * i) for i in range(n)))


TABLE = CompTable({1: _leg(1, 1.0), 2: _leg(2, -2.0)})
TEXT = table_csv_text(TABLE)  # with its integrity record, as `station table` writes it
BARE = TEXT.split("\n", 1)[1]  # the same rows without it: a hand-made file (or one from before the record)


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """A simulated two-leg drive on 127.0.0.1 whose both banks hold tables, and a working folder
    (the audit log goes to its runs/)."""
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    work = tmp_path_factory.mktemp("bench")
    old = os.getcwd()
    os.chdir(work)
    plants = {i + 1: LegPlant(c, seed=i + 1) for i, c in enumerate(default_leg_configs(0, 2))}
    server = SimDriveServer(plants, VirtualClock(0.0), PROFILE)
    url = f"tcp://127.0.0.1:{server.start_tcp()}"
    Path("older.csv").write_text(table_csv_text(CompTable({1: _leg(1, 3.0), 2: _leg(2, 3.0)})))
    Path("good.csv").write_text(TEXT)
    for name in ("older.csv", "good.csv"):  # bank 1 then bank 0: neither is empty
        assert main(["push", name, "--leg", "1-2", "--drive", url, "--yes"]) == 0
    try:
        yield server, url
    finally:
        server.stop()
        os.chdir(old)


def drive_state(server, url):
    """Per leg: (active bank, bank 0, bank 1) read over Modbus, and the drive's write counter."""
    state = {}
    for leg in (1, 2):
        ax = ModbusServoAxis(ModbusBus.from_url(url, timeout_s=0.5), leg, PROFILE)
        try:
            state[leg] = (ax.active_bank(), ax.read_table(0), ax.read_table(1), server.request_counts(leg)[1])
        finally:
            ax.close()
    return state


def push(capsys, name: str, text: str, url: str, leg: str = "2"):
    Path(name).write_text(text)
    rc = main(["push", name, "--leg", leg, "--drive", url, "--yes"])
    out, err = capsys.readouterr()
    return rc, out, err


def _cut_mid_row(text: str) -> str:
    """The reproduction: cut in leg 2's third row, after `1.` of its last field."""
    lines = text.splitlines(keepends=True)
    third = [i for i, line in enumerate(lines) if line.startswith("2,")][2]
    row = lines[third].rstrip("\n").split(",")
    row[3] = "1."
    return "".join(lines[:third]) + ",".join(row)


CASES = [
    ("cut mid-row, with the record", _cut_mid_row(TEXT),
     r"does not match its integrity record \(row 1\): the record says 62 table rows, sha256 [0-9a-f]{16}\.\.\., "
     r"the file has 34 table rows, sha256 [0-9a-f]{16}\.\.\. \(cut short: 28 row\(s\) missing\)"),
    ("cut mid-row, no record", _cut_mid_row(BARE),
     r"row 35: the last row has no line end, so it may be cut mid-field"),
    ("cut after a whole row, no record", BARE[:BARE.index("2,-60.000000")],
     r"leg 2: covers -90.000 .. -66.000 mm, not the leg's stroke -90.000 .. \+90.000 mm .* it may be cut short"),
    ("one digit edited", TEXT.replace("2,-60.000000,-1.", "2,-60.000000,-2.", 1),
     r"the file has 62 table rows, .* \(edited: same row count, different content\)"),
    ("a row deleted", TEXT.replace(TEXT.splitlines(keepends=True)[20], "", 1), r"\(cut short: 1 row\(s\) missing\)"),
    ("the record edited", TEXT.replace("rows=62", "rows=61", 1), r"\(1 row\(s\) added\)"),
]


@pytest.mark.parametrize("name, text, words", CASES, ids=[c[0] for c in CASES])
def test_a_cut_or_edited_table_is_refused_and_the_drive_is_unchanged(capsys, bench, name, text, words):
    import re

    server, url = bench
    before = drive_state(server, url)
    rc, out, err = push(capsys, "table_trunc.csv", text, url)
    assert rc == 2 and err.count("\n") == 1 and err.startswith("station push: error: table_trunc.csv"), err
    assert re.search(words, err), err
    assert "Nothing was written to the drive" in err and "make the table again" in err
    assert drive_state(server, url) == before, "bank contents, active bank or the write counter changed"
    print(f"\n[{name}] {err.strip()}")


def test_a_hand_made_table_that_is_whole_is_pushed_and_said_unverified(capsys, bench):
    server, url = bench
    rc, out, err = push(capsys, "hand.csv", BARE, url, leg="1")
    assert rc == 0, err
    warnings = [line for line in out.splitlines() if line.startswith("warning:")]
    assert warnings == [f"warning: hand.csv has no integrity record (made by hand, or before the station wrote one): "
                        f"table accepted as complete (leg 1: 31 rows -90 .. +90 mm step 6 mm; whole rows, even steps; "
                        f"the push checks it covers the stroke) but unverified"], out
    active, *banks, _ = drive_state(server, url)[1]
    assert table_sha256(banks[active]) == table_sha256(PROFILE_QUANTIZED(TABLE.legs[1]))


def PROFILE_QUANTIZED(t: LegTable):  # noqa: N802 - the table as the drive holds it
    from drivers.modbus.client import table_spec

    return quantize(t.to_bank(), table_spec(PROFILE))


# -- every cut, every leg: refused, or read whole ------------------------------------------------------

def _read_leg(path: Path, leg: int) -> LegTable | None:
    """The leg as a push would take it (the file read, and a file without a record checked to
    cover the drive's stroke), or None when refused."""
    try:
        table, source = load_leg_table(path, leg)
        if source["table_integrity"] == UNVERIFIED:
            check_covers_stroke(table, SOFT, str(path))
    except (InputError, TableRefused):
        return None
    return table


def _same(a: LegTable, b: LegTable) -> bool:
    return (a.point_count == b.point_count and abs(a.start_mm - b.start_mm) < 1e-9 and abs(a.step_mm - b.step_mm) < 1e-9
            and np.allclose(a.error_fwd_um, b.error_fwd_um, atol=5e-5)
            and np.allclose(a.error_rev_um, b.error_rev_um, atol=5e-5))


SMALL = CompTable({1: _leg(1, 1.0, step=15.0), 2: _leg(2, -2.0, step=15.0)})  # 13 points a leg: every cut in ~3 s


@pytest.mark.parametrize("which", ["with the record", "without it"])
def test_every_cut_of_a_table_file_is_refused_or_read_whole(tmp_path, which):
    text = table_csv_text(SMALL)
    text = text if which == "with the record" else text.split("\n", 1)[1]
    path = tmp_path / "cut.csv"
    accepted = {1: 0, 2: 0}
    for n in range(len(text) + 1):
        path.write_text(text[:n])
        for leg in (1, 2):
            got = _read_leg(path, leg)
            if got is not None:
                assert _same(got, SMALL.legs[leg]), f"cut at byte {n} of {len(text)}: leg {leg} read as a shorter table"
                accepted[leg] += 1
    if which == "with the record":  # only the whole file, with or without its final line end
        assert accepted == {1: 2, 2: 2}
    else:  # only cuts at a line end: leg 1 whole in those after its last row (but the one leaving leg 2 a single
        # point, which fails the whole file), leg 2 only in the whole file
        assert accepted == {1: SMALL.legs[2].point_count, 2: 1}
    print(f"\n{which}: {len(text) + 1} cuts x 2 legs; accepted whole: {accepted}; every other refused")


@settings(max_examples=2000 if LONG else 300, deadline=None, derandomize=not LONG, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(0, len(TEXT.encode()) - 1), st.integers(0, 255))
def test_single_byte_edits_are_refused_or_read_the_same(tmp_path, at, value):
    data = bytearray(TEXT.encode())
    if data[at] == value:
        return
    data[at] = value
    path = tmp_path / "edit.csv"
    path.write_bytes(bytes(data))
    for leg in (1, 2):
        got = _read_leg(path, leg)
        # accepted only when the edit changed nothing a reader parses (a line end for another line end)
        assert got is None or _same(got, TABLE.legs[leg]), f"byte {at} -> {value}: leg {leg} read differently"


@settings(max_examples=200 if LONG else 10, deadline=None, derandomize=not LONG, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_pushed_cuts_and_edits_never_leave_a_partial_table_active(capsys, bench, data):
    """Through the CLI and the drive: a cut or a one-byte edit is refused with the drive unchanged,
    or the whole table is active."""
    server, url = bench
    text = data.draw(st.sampled_from([TEXT, BARE]), label="file")
    raw = bytearray(text.encode())
    if data.draw(st.booleans(), label="cut (else edit)"):
        raw = raw[:data.draw(st.integers(0, len(raw)), label="cut at")]
    else:
        raw[data.draw(st.integers(0, len(raw) - 1), label="byte")] = data.draw(st.integers(0, 255), label="value")
    before = drive_state(server, url)
    Path("gen.csv").write_bytes(bytes(raw))
    rc = main(["push", "gen.csv", "--leg", "2", "--drive", url, "--yes"])
    out, err = capsys.readouterr()
    after = drive_state(server, url)
    if rc == 0:
        active, *banks, _ = after[2]
        assert table_sha256(banks[active]) == table_sha256(PROFILE_QUANTIZED(TABLE.legs[2])), "a partial table is active"
    else:
        assert rc == 2 and err.count("\n") == 1, err
        assert after == before, "refused, but the drive changed"


# -- models ------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    from drivers.plant.leg import PlantConfig

    cfg = PlantConfig(reversal_um=2.0).only("backlash", "lead", "longwave", "noise")
    model = fit(synth_session({1: cfg, 2: cfg}, np.linspace(-90, 90, 61), cycles=3, seed=3), lead_mm=5.0)
    path = tmp_path_factory.mktemp("model") / "model.json"
    save_model(model, path, "runs/s.h5", "0" * 64)
    return model, path


def station(capsys, *argv):
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def test_a_model_written_by_the_station_is_verified_and_an_edited_one_refused(tmp_path, capsys, model_file):
    _, path = model_file
    assert load_model(path).integrity == VERIFIED
    doc = json.loads(path.read_text())
    assert doc["integrity"]["legs"] == 2 and len(doc["integrity"]["sha256"]) == 64
    edited = tmp_path / "edited.json"
    edited.write_text(path.read_text().replace('"n_cycles": 3', '"n_cycles": 2', 1))
    rc, out, err = station(capsys, "table", str(edited), "--out", str(tmp_path / "t.csv"))
    assert rc == 2 and err.count("\n") == 1
    assert "edited.json: does not match its integrity record: the record says 2 legs" in err and "fit the recording again" in err
    assert not (tmp_path / "t.csv").exists()
    bare = tmp_path / "bare.json"
    doc.pop("integrity")
    bare.write_text(json.dumps(doc))
    rc, out, err = station(capsys, "table", str(bare), "--out", str(tmp_path / "t.csv"))
    assert rc == 0, err
    assert [line for line in out.splitlines() if line.startswith("warning:")] == [
        f"warning: {bare} has no integrity record (made by hand, or before the station wrote one): model accepted as "
        "complete (legs 1, 2, every field checked) but unverified"]


@pytest.mark.parametrize("kind, content, words", [
    ("table", TEXT, "is a table CSV, not a model"),
    ("session", b"\x89HDF\r\n\x1a\n" + bytes(100), "is a session file (HDF5), not a model"),
    ("serials", "leg,serial\n1,HX-1\n", "this is a serials list, not a model"),
])
def test_a_wrong_kind_of_file_given_as_a_model_is_named(tmp_path, capsys, kind, content, words):
    path = tmp_path / "some_file"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    rc, out, err = station(capsys, "table", str(path), "--out", str(tmp_path / "t.csv"))
    assert rc == 2 and err.count("\n") == 1 and words in err, err
    assert "station fit" in err  # what makes a model


def test_a_model_given_as_a_table_is_named(capsys, bench, model_file):
    _, path = model_file
    server, url = bench
    rc, out, err = station(capsys, "push", str(path), "--leg", "1", "--drive", url, "--yes")
    assert rc == 2 and "this is a model, not a table" in err and "station table MODEL.json" in err, err


def test_table_refuses_a_step_or_range_beyond_the_stroke(tmp_path, capsys, model_file):
    _, path = model_file
    out_csv = tmp_path / "t.csv"
    rc, out, err = station(capsys, "table", str(path), "--out", str(out_csv), "--step", "1000")
    assert rc == 2 and err.count("\n") == 1 and not out_csv.exists()
    assert "leg 1: a 1000 mm step is longer than the leg's stroke (-90 .. +90 mm, 180 mm): the table would end " \
           "at +910 mm" in err
    rc, out, err = station(capsys, "table", str(path), "--out", str(out_csv), "--step", "100")
    assert rc == 2 and err.count("\n") == 1 and not out_csv.exists()
    assert "a 100 mm step makes the table cover -90 .. +110 mm, beyond the drive's soft limits -95 .. +95 mm" in err
    assert "e.g. 90 mm" in err


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(scope="module")
def worse_model(tmp_path_factory, model_file):
    """The model with leg 2's held-out range 25 % above its range before: a reduction of -25 %."""
    model, _ = model_file
    leg = model.legs[2]
    stats = dataclasses.replace(leg.stats, heldout_range_um=leg.stats.range_before_um * 1.25)
    leg.stats, saved = stats, leg.stats
    try:
        path = tmp_path_factory.mktemp("worse") / "worse.json"
        save_model(model, path, "runs/s.h5", "0" * 64)
    finally:
        leg.stats = saved
    return path


def test_a_model_worse_on_held_out_data_asks_first(tmp_path, capsys, monkeypatch, worse_model):
    out_csv = tmp_path / "t.csv"
    rc, out, err = station(capsys, "table", str(worse_model), "--out", str(out_csv))  # no terminal: refused
    assert rc == 2 and err.count("\n") == 1 and not out_csv.exists()
    assert "leg 2: held-out range reduction (%) = -25: the model made the leg's error worse on the cycles held out" in err
    assert "--accept-implausible" in err
    monkeypatch.setattr(sys, "stdin", Tty("n\n"))
    rc, out, err = station(capsys, "table", str(worse_model), "--out", str(out_csv))
    assert rc == 2 and "Make the table anyway? [y/N]" in out and "not confirmed" in err and not out_csv.exists()
    monkeypatch.setattr(sys, "stdin", Tty("y\n"))
    rc, out, err = station(capsys, "table", str(worse_model), "--out", str(out_csv))
    assert rc == 0 and out_csv.exists(), err
    assert "warning: leg 2: held-out range reduction (%) = -25" in out and "(kept: --accept-implausible)" in out
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    rc, out, err = station(capsys, "table", str(worse_model), "--out", str(out_csv), "--force", "--accept-implausible")
    assert rc == 0 and "(kept: --accept-implausible)" in out, err


# -- serials lists -----------------------------------------------------------------------------------

def test_a_serials_list_proves_itself(tmp_path):
    path = write_serials_file(tmp_path / "serials.csv", {1: {"serial": "HX-0001", "leg_type": "HX300"},
                                                         2: {"serial": "HX-0002"}})
    text = path.read_text()
    assert text.splitlines()[0].startswith("# integrity: serials rows=2 sha256=")
    assert read_serials_file_checked(path) == ({1: {"serial": "HX-0001", "leg_type": "HX300"},
                                                2: {"serial": "HX-0002"}}, VERIFIED)
    cut = tmp_path / "cut.csv"
    cut.write_text(text[:-4])  # "HX-0002" cut to "HX-0": still a valid serial
    with pytest.raises(InputError, match=r"cut.csv: does not match its integrity record .* the record says 2 serials "
                                         r"rows, .* the file has 2 serials rows, .*\(edited"):
        read_serials_file_checked(cut)
    cut.write_text(text.split("\n", 1)[1][:-4])  # the same without its record: the last row has no line end
    with pytest.raises(InputError, match=r"cut.csv, row 3: the last row has no line end"):
        read_serials_file_checked(cut)
    cut.write_text(text.split("\n", 1)[1])
    assert read_serials_file_checked(cut)[1] == UNVERIFIED


def test_both_front_ends_refuse_a_model_worse_on_held_out_data_unless_accepted(worse_model):
    """The service the CLI and the UI's Compensation page ("Make anyway") make tables through."""
    from procedures.metrology.plausibility import ImplausibleError
    from station.services.table_jobs import make_checked_table

    model = load_model(worse_model)
    with pytest.raises(ImplausibleError, match=r"leg 2: held-out range reduction \(%\) = -25") as exc:
        make_checked_table(model)
    assert [f.where for f in exc.value.findings] == ["leg 2: held-out range reduction (%)"]
    table, warnings = make_checked_table(model, accept_implausible=True)
    assert list(table.legs) == [1, 2] and len(warnings) == 1 and warnings[0].startswith("warning: leg 2: held-out")
    table, warnings = make_checked_table(model, legs=[1])  # leg 1's model is fine: nothing to ask
    assert warnings == []


@pytest.mark.parametrize("content, words", [
    (TEXT, "this is a table, not a session"),
    ("leg,serial\n1,HX-1\n", "this is a serials list, not a session"),
])
def test_a_wrong_kind_of_file_given_as_a_session_is_named(tmp_path, capsys, content, words):
    path = tmp_path / "thing.h5"
    path.write_text(content)
    rc, out, err = station(capsys, "fit", str(path), "--out", str(tmp_path / "m.json"))
    assert rc == 2 and err.count("\n") == 1 and words in err, err
