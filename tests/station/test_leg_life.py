"""A leg's life through the command line on the simulated rig (issue 33.1, 31.7): station A
calibrates HX-0001 as found, pushes a table, verifies it as left; station B calibrates it again.
Every session carries its stage (the file's root attribute and the catalog), history and legs
count calibrations as calibrations, and no drift figure comes from sessions minutes apart. A
sweep of the compensated leg asks (or needs --yes), records the active table and is stage
"other", not a calibration.

One scenario for the module (about 10 s): the two stations share a catalog (an SQLite file named
as `[catalog] url`, the shared-catalog path of a PostgreSQL one: tests/catalog covers PostgreSQL).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from procedures.io.recording.reader import read_session
from procedures.io.recording.stage import active_tables
from station.cli import main

pytestmark = pytest.mark.timeout(300)

SERIAL = "HX-0001"
SWEEP = ["--legs", "1", "--step", "15", "--cycles", "2", "--time-scale", "0"]


def _config(tmp: Path, station: str) -> Path:
    runs = tmp / station
    runs.mkdir()
    path = tmp / f"{station}.toml"
    path.write_text(f'[station]\nid = "{station}"\noperator = "ana"\nrecordings_dir = "{runs}"\n'
                    '[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n'
                    f'[catalog]\nurl = "sqlite:///{tmp / "shared.sqlite"}"\n'
                    f'[legs.1]\nserial = "{SERIAL}"\nleg_type = "HX300"\n')
    return path


@pytest.fixture(scope="module")
def life(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("life")
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STATION_CATALOG", "on")  # tests/conftest.py turns catalog writes off elsewhere
        a, b = _config(tmp, "ST-A"), _config(tmp, "ST-B")
        ra, rb = tmp / "ST-A", tmp / "ST-B"
        done: dict[str, object] = {"tmp": tmp, "a": a, "b": b}

        def step(name, *argv):
            capture = _Capture()
            rc = capture.run(argv)
            done[name] = (rc, capture.out, capture.err)
            return rc

        assert step("cal_a", "sweep", "--config", a, *SWEEP, "--out", ra / "cal.h5") == 0
        assert step("fit", "fit", ra / "cal.h5", "--out", ra / "model.json", "--config", a) == 0
        assert step("table", "table", ra / "model.json", "--out", ra / "table.csv", "--config", a) == 0
        assert step("push", "push", ra / "table.csv", "--leg", "1", "--config", a, "--yes") == 0
        assert step("verify", "verify", "--leg", "1", "--config", a, "--before", ra / "cal.h5", "--out", ra / "ver.h5",
                    "--noise-seed", "3", "--time-scale", "0") in (0, 1)
        # the table stays active at station A: a sweep now measures the compensated leg
        step("comp_refused", "sweep", "--config", a, *SWEEP, "--out", ra / "comp.h5")
        done["comp_written_when_refused"] = (ra / "comp.h5").exists()
        step("comp_yes", "sweep", "--config", a, *SWEEP, "--out", ra / "comp.h5", "--yes")
        assert step("cal_b", "sweep", "--config", b, *SWEEP, "--out", rb / "cal.h5") == 0
        # what waits in an outbox (a forward that met a busy shared file under load) goes now
        step("sync_a", "catalog", "sync", "--config", a)
        step("sync_b", "catalog", "sync", "--config", b)
        step("history", "history", SERIAL, "--config", b)
        step("history_json", "history", SERIAL, "--config", b, "--json")
        step("legs", "legs", "--config", b)
        yield done


class _Capture:
    """Runs one command with stdout and stderr captured (a module fixture has no capsys)."""

    def run(self, argv) -> int:
        import contextlib
        import io

        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main([str(x) for x in argv])
        self.out, self.err = out.getvalue(), err.getvalue()
        return rc


def test_every_session_records_its_stage(life):
    ra, rb = life["tmp"] / "ST-A", life["tmp"] / "ST-B"
    stages = {name: read_session(p).attrs.get("stage") for name, p in
              (("cal_a", ra / "cal.h5"), ("ver", ra / "ver.h5"), ("comp", ra / "comp.h5"), ("cal_b", rb / "cal.h5"))}
    assert stages == {"cal_a": "as_found", "ver": "as_left", "comp": "other", "cal_b": "as_found"}
    # station B keeps its own simulated drive memory: it starts with no table, station A's leg has one
    assert active_tables(read_session(rb / "cal.h5").devices) == {}


def test_history_counts_calibrations_and_verifications_and_refuses_drift_over_minutes(life):
    rc, out, err = life["history"]
    assert rc == 0, err
    assert "(shared)" in out.splitlines()[0]
    steps = {k: v[:1] + (v[2][-300:],) for k, v in life.items() if isinstance(v, tuple)}  # rc, err of each step
    assert "2 calibration(s) as found, 1 verification(s) as left" in out, (out, steps)
    (drift,) = [ln for ln in out.splitlines() if ln.startswith("drift ")]
    assert "not computed" in drift and "under the minimum interval of 30 days" in drift and "um/month" not in drift
    stages = [ln.split()[2:4] for ln in out.splitlines() if ln[:4] == "2026" or ln[:2] == "20"]
    assert ["as", "found"] in stages and ["as", "left"] in stages and ["adjustment", "ST-A"] in stages
    h = json.loads(life["history_json"][1])
    assert h["counts"] == {"calibrations": 2, "verifications": 1}
    cals = [r for r in h["rows"] if r["kind"] == "session" and r["stage"] == "as_found"]
    assert [r["station_id"] for r in cals] == ["ST-A", "ST-B"]
    assert h["last_calibration_utc"] == cals[-1]["time_utc"]  # the last as-found one, station B's
    (d,) = h["drift"]
    assert d["refused"] and all(v is None for v in d["um_per_month"].values()) and d["days"] < 1
    # the compensated sweep is in the history as stage other, not a calibration
    assert [r["stage"] for r in h["rows"] if r["kind"] == "session"].count("other") == 1


def test_legs_counts_calibrations_and_verifications(life):
    rc, out, err = life["legs"]
    assert rc == 0, err
    (row,) = [ln.split() for ln in out.splitlines() if ln.startswith(SERIAL)]
    assert row[:4] == [SERIAL, "HX300", "2", "1"] and row[5] == "ST-B"


def test_compensated_sweep_asks_or_needs_yes(life):
    rc, out, err = life["comp_refused"]
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err
    assert "leg(s) 1: a compensation table is active (bank" in lines[0] and "--yes" in lines[0]
    assert "nothing moved" in lines[0] and life["comp_written_when_refused"] is False
    rc, out, err = life["comp_yes"]
    assert rc == 0, err
    s = read_session(life["tmp"] / "ST-A" / "comp.h5")
    (recorded,) = active_tables(s.devices).values()
    pushed = json.loads(s.devices["leg1_compensation_table"])
    # the table pushed is the one recorded: its points, and the table CSV's rows of leg 1
    rows = [ln for ln in (life["tmp"] / "ST-A" / "table.csv").read_text().splitlines() if ln[:2] == "1,"]
    assert pushed["enabled"] and pushed["points"] == len(rows) > 0 and f"{len(rows)} points from" in recorded
    assert s.stage == "other"
