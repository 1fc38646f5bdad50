"""The unit-slip checks of tables and pushes are the service's (station.services.table_jobs), not a
front end's: called without `accept_implausible`, the service itself refuses a table correcting far
more than the recorded error, and a push of corrections that look like nm (on the simulated drive, a
real Modbus server on loopback): logged, nothing written, the previous table active. The audit line
is the one `station push` writes."""

from __future__ import annotations

from pathlib import Path

import pytest

from procedures.compensation.audit import read_entries
from procedures.compensation.push import table_sha256
from procedures.compensation.table import write_table_csv
from procedures.metrology.plausibility import ImplausibleError, Override
from procedures.io.recording.reader import read_session
from station.cli import main
from station.services.analysis import analyse_session
from station.services.config import StationConfig
from station.services.session_identity import station_audit_log
from station.services.table_jobs import load_leg_table, make_checked_table, push_job, push_legs_job
from station.services.wiring import open_drive
from tests.tooling import slipped_model

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "recordings" / "calibration-6legs.h5"
LEGS = (1, 2)


@pytest.fixture(scope="module")
def model():
    return analyse_session(read_session(SAMPLE), fit_method="default", fit_options={"legs": LEGS}).model


def _cfg(folder: Path) -> StationConfig:
    cfg = StationConfig(operator="test")
    cfg.recordings_dir = str(folder / "runs")
    cfg.drive.url = "sim"
    return cfg.with_sim_memory()


def _held(drive) -> dict[int, tuple[int, str]]:
    """Each leg's active bank and the sha256 of the table in it, read from the drive."""
    return {leg: (a.active_bank(), table_sha256(a.read_table(a.active_bank()))) for leg, a in drive.axes.items()}


def test_the_service_refuses_a_table_correcting_far_more_than_the_error(model):
    table, warnings = make_checked_table(model)
    assert set(table.legs) == set(LEGS) and warnings == []
    slipped = slipped_model(model)
    with pytest.raises(ImplausibleError) as refused:
        make_checked_table(slipped)
    text = str(refused.value)
    assert text.startswith("leg 1: correction span (um) = ") and f"peak to peak in {SAMPLE}" in text
    assert "(and 1 more implausible value(s)); correct it, or add --accept-implausible" in text
    with pytest.raises(ImplausibleError, match="or confirm it below if the values are right"):
        make_checked_table(slipped, override=Override(how="confirm it below", kept="confirmed"))
    table, warnings = make_checked_table(slipped, accept_implausible=True)
    assert [w.split(":")[1].strip() for w in warnings] == [f"leg {leg}" for leg in LEGS]
    assert all(w.endswith("(kept: --accept-implausible)") for w in warnings)
    assert 100.0 < max(max(map(abs, t.error_fwd_um)) for t in table.legs.values()) <= 300.0


def test_the_push_job_refuses_nm_values_before_the_drive_is_written(model, tmp_path):
    cfg = _cfg(tmp_path)
    audit = station_audit_log(cfg)
    table, _ = make_checked_table(slipped_model(model), accept_implausible=True)
    sources = {leg: {"path": "t.csv", "leg": leg} for leg in LEGS}
    with open_drive(cfg, LEGS) as drive:
        before = _held(drive)
        job = push_job(drive.axes[1], table.legs[1], audit=audit, drive_url=drive.url, source=sources[1], confirm=None,
                       table_name="t.csv")
        assert job.implausible and job.outcome == "refused" and job.warnings == []
        message = job.finished.message
        assert message.startswith("t.csv, leg 1, point ") and " mm), field error_" in message  # made, not read: points
        assert "looks like nm in an um field" in message and "not 100 um and more" in message
        assert message.endswith("add --accept-implausible if the values are right. Nothing was written to the drive.")
        job = push_legs_job(drive.axes, table.legs, audit=audit, drive_url=drive.url, sources=sources, confirm=None)
        assert job.implausible and job.outcome == "refused" and job.finished.message.startswith("t.csv, leg 1, point ")
        assert _held(drive) == before  # the previous tables stay active, untouched
        entries = read_entries(audit.path)[0]
        assert [(e.action, e.leg, e.outcome, e.source) for e in entries] == [("push", 1, "refused", sources[1])] * 2
        # accepted: pushed, the warning kept, and the audit entries say what was accepted
        job = push_job(drive.axes[2], table.legs[2], audit=audit, drive_url=drive.url, source=sources[2], confirm=None,
                       accept_implausible=True, table_name="t.csv")
        assert job.ok and not job.implausible and len(job.warnings) == 1 and "t.csv, leg 2, point " in job.warnings[0]
        held = _held(drive)
        assert held[1] == before[1] and held[2][0] != before[2][0]
    last = read_entries(audit.path)[0][-1]
    assert (last.leg, last.outcome) == (2, "ok") and last.source["implausible_accepted"] == job.warnings


def test_the_service_writes_the_refusal_station_push_writes(model, tmp_path, monkeypatch):
    table, _ = make_checked_table(slipped_model(model), accept_implausible=True)
    entries = {}
    for who in ("cli", "service"):
        folder = tmp_path / who
        folder.mkdir()
        monkeypatch.chdir(folder)
        csv = write_table_csv(table, "t.csv")
        if who == "cli":
            assert main(["push", "t.csv", "--leg", "1", "--sim", "--yes"]) == 2
        else:
            cfg = _cfg(Path("."))
            leg_table, source = load_leg_table("t.csv", 1)
            with open_drive(cfg, 1) as drive:
                push_job(drive.axis, leg_table, audit=station_audit_log(cfg), drive_url=drive.url, source=source,
                         confirm=None, table_name=str(csv))
        (entry,) = read_entries(folder / "runs" / "audit.jsonl")[0]
        entries[who] = (entry.action, entry.leg, entry.outcome, entry.message, entry.source)
    assert entries["cli"] == entries["service"]
    assert entries["cli"][3].startswith("t.csv, leg 1, row ")
