"""Issuing calibration certificates (docs/certificate.md): report numbers, revisions, immutable
files. `station certificate` calls `issue_certificate` with sessions it read; the catalog (by
serial) can call it with the sessions it finds, since it takes sessions, not file names.

- Report number: STATION-YYYYMMDD-NNNN, NNNN from a counter file (<recordings_dir>/
  certificate-counter.json) incremented under an exclusive lock and never decremented, so a
  number is never issued twice, even by two processes at once.
- Files, in the certificates folder (default <recordings_dir>/certificates): REPORT_rN.pdf and
  REPORT_rN.json, created with no-overwrite links (an existing file is never replaced), and
  REPORT.index.json listing the revisions; a revision (--revise REPORT) adds REPORT_r(N+1).* and
  marks revision N superseded in the index: the issued files themselves never change.
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import hashlib
import json
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from procedures.reporting import certificate
from procedures.engine.errors import InputError
from procedures.io.atomic import write_bytes_atomic  # the index is whole or old
from station.services.report_jobs import session_decisions

COUNTER_NAME = "certificate-counter.json"
FOLDER_NAME = "certificates"
_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


@dataclass(frozen=True)
class Issued:
    report_no: str
    revision: int
    pdf: Path
    json: Path
    index: Path
    content: dict[str, Any]


def _create_new(path: Path, data: bytes) -> None:
    """Write `path` whole or not at all, and never over an existing file (link(2) refuses)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o444)  # an issued certificate is read-only
        os.link(tmp, path)
    except FileExistsError:
        raise InputError(f"{path}: exists; an issued certificate is never overwritten") from None
    finally:
        Path(tmp).unlink(missing_ok=True)


def next_report_no(counter_path: Path, station_id: str, day: _dt.date) -> str:
    """STATION-YYYYMMDD-NNNN with NNNN the next value of the counter file (created at 1)."""
    counter_path.parent.mkdir(parents=True, exist_ok=True)
    with open(counter_path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        fh.seek(0)
        text = fh.read().strip()
        try:
            last = int(json.loads(text)["last"]) if text else 0
        except (ValueError, KeyError, TypeError):
            raise InputError(f"{counter_path}: not a certificate counter ({text[:40]!r}); it must hold "
                             '{"last": N}: restore it from a backup, never reset it') from None
        n = last + 1
        fh.seek(0)
        fh.truncate()
        fh.write(json.dumps({"last": n}) + "\n")
        fh.flush()
        os.fsync(fh.fileno())
    return f"{_SAFE.sub('-', station_id or 'station')}-{day:%Y%m%d}-{n:04d}"


def _index_path(folder: Path, report_no: str) -> Path:
    return folder / f"{report_no}.index.json"


def read_index(folder: Path, report_no: str) -> dict[str, Any]:
    p = _index_path(folder, report_no)
    try:
        return json.loads(p.read_text())
    except FileNotFoundError:
        raise InputError(f"{p}: no certificate {report_no} in {folder} (--revise needs an issued report number)") from None
    except ValueError:
        raise InputError(f"{p}: not a certificate index (damaged JSON)") from None


def table_record(path: str | os.PathLike | None) -> dict[str, Any] | None:
    if path is None:
        return None
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise InputError(f"--table {p}: cannot read it ({exc.strerror})") from None
    return {"file": p.name, "sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}


def _active_table_sha256(session, leg: int) -> str | None:
    """The sha256 of the table the session recorded active on `leg` (procedures.compensation.applied_table)."""
    try:
        return json.loads(session.devices.get(f"leg{leg}_compensation_table") or "{}").get("sha256") or None
    except (TypeError, ValueError, AttributeError):
        return None


def _instrument(session) -> dict | None:
    """The laser as the session's identity recorded it (None for a session without identity)."""
    if not session.identity.recorded:
        return None
    ins = session.identity.instrument
    return {"model": ins.model, "serial": ins.serial, "calibrated_on": ins.calibrated_on}


def pick_leg(session, leg: int | None) -> int:
    if leg is not None:
        if leg not in session.legs:
            raise InputError(f"{session.path}: no leg {leg} (it holds legs {session.legs})")
        return leg
    if len(session.legs) != 1:
        raise InputError(f"{session.path}: holds legs {session.legs}; a certificate is of one leg: say which with --leg")
    return session.legs[0]


def _as_left_leg(as_found, as_left, leg: int) -> int:
    """Where `as_left` measured the leg `as_found` measured at `leg`, found by its serial: the
    same position when it holds that serial there, else the one position that does (a leg
    verified after being remounted elsewhere). InputError when none, or several, do."""
    serial = as_found.identity.leg(leg).serial
    holding = [n for n in as_left.legs if as_left.identity.leg(n).serial == serial]
    if leg in holding:
        return leg
    if len(holding) == 1:
        return holding[0]
    if holding:
        raise InputError(f"{as_left.path}: legs {holding} all carry serial {serial}; a session's legs need serials "
                         "of their own to tell which one is the leg certified")
    measured = ", ".join(as_left.identity.leg(n).serial or "(no serial)" for n in as_left.legs)
    raise InputError(f"{as_left.path} measured leg {measured} but {as_found.path} measured leg {serial}: "
                     "as found and as left must be the same leg")


def issue_certificate(as_found, *, leg: int | None = None, as_left=None, table: str | os.PathLike | None = None,
                      lab: dict | None = None, customer: str = "", folder: str | os.PathLike,
                      counter_path: str | os.PathLike, revise: str | None = None, reason: str = "",
                      tolerances: dict | None = None, issued_utc: str | None = None,
                      station_id: str = "", table_leg_sha256: str | None = None) -> Issued:
    """Issue a certificate of `leg` from the sessions `as_found` (and `as_left`, a verification),
    both procedures.io.recording.reader.Session; `table` the compensation table pushed (its sha256 is
    stated); `revise` the report number of a certificate this one corrects (`reason` says why).
    `tolerances` {type: Tolerance.to_json()} (None: the sessions' recorded ones); `station_id`
    names the issuing station in the report number when the session does not record one;
    `table_leg_sha256` the sha256 of the leg's rows of `table` as its holder stores them
    (station.services.table_jobs.expected_tables), checked against the table the as-left session found active."""
    folder, counter_path = Path(folder), Path(counter_path)
    leg = pick_leg(as_found, leg)
    if not as_found.identity.leg(leg).serial:
        raise InputError(f"{as_found.path}: leg {leg} has no serial recorded; a certificate must identify the item "
                         "calibrated: sweep it with --serial LEG=SERIAL (or [legs.N] serial) and certify that session")
    found = session_decisions(as_found, tolerances=tolerances, stage="as_found")
    left = session_decisions(as_left, tolerances=tolerances, stage="as_left") if as_left is not None else None
    left_leg = _as_left_leg(as_found, as_left, leg) if left is not None else None
    folder.mkdir(parents=True, exist_ok=True)
    issued_utc = issued_utc or certificate.now_utc()
    supersedes = None
    if revise:
        index = read_index(folder, revise)
        if not reason:
            raise InputError("--revise needs --reason: a corrected certificate says what was corrected")
        last = index["revisions"][-1]
        report_no, revision = revise, int(last["revision"]) + 1
        supersedes = {"report_no": revise, "revision": last["revision"], "sha256_pdf": last["sha256_pdf"],
                      "reason": reason}
    else:
        station = as_found.identity.station.id or station_id or "station"
        report_no = next_report_no(counter_path, station, _dt.date.fromisoformat(issued_utc[:10]))
        index, revision = {"report_no": report_no, "revisions": []}, 1
    table_rec = table_record(table)
    if table_rec is not None and table_leg_sha256:
        table_rec["leg_rows_sha256"] = table_leg_sha256
        if as_left is not None:
            active = _active_table_sha256(as_left, left_leg)
            table_rec["active_as_left_sha256"] = active
            table_rec["matches_as_left"] = active == table_leg_sha256 if active else None
    try:
        cert = certificate.content(found, leg, report_no=report_no, revision=revision, issued_utc=issued_utc,
                                   lab=lab or {}, customer=customer, as_left=left, table=table_rec,
                                   supersedes=supersedes, instrument=_instrument(as_found), as_left_leg=left_leg)
    except (KeyError, ValueError) as exc:
        raise InputError(f"{as_found.path}: {exc}") from None
    stem = f"{report_no}_r{revision}"
    pdf_path, json_path = folder / f"{stem}.pdf", folder / f"{stem}.json"
    pdf_bytes = certificate.pdf(cert)
    _create_new(pdf_path, pdf_bytes)
    try:
        _create_new(json_path, (json.dumps(cert, indent=2, allow_nan=False) + "\n").encode())
    except BaseException:
        os.chmod(pdf_path, 0o644)
        pdf_path.unlink()
        raise
    for r in index["revisions"]:
        if r["status"] == "issued":
            r.update(status="superseded", superseded_by=revision, superseded_utc=issued_utc, reason=reason)
    index["revisions"].append({"revision": revision, "status": "issued", "issued_utc": issued_utc,
                               "pdf": pdf_path.name, "json": json_path.name,
                               "sha256_pdf": hashlib.sha256(pdf_bytes).hexdigest(), "serial": cert["item"]["serial"],
                               "as_found_session": cert["as_found"]["session_sha256"],
                               "as_left_session": (cert["as_left"] or {}).get("session_sha256")})
    index_path = _index_path(folder, report_no)
    write_bytes_atomic(index_path, (json.dumps(index, indent=2) + "\n").encode())
    return Issued(report_no, revision, pdf_path, json_path, index_path, cert)
