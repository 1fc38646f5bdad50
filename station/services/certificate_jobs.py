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
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from procedures.reporting import certificate, decision
from procedures.vocabulary import InputError
from procedures.io.recording.stage import AS_FOUND, AS_LEFT, stage_of_session
from procedures.io.atomic_outputs import write_bytes_atomic  # the index is whole or old
from station.services.report_jobs import session_decisions
from station.services.job import OfflineJob

if TYPE_CHECKING:  # annotations only: the catalog (SQLAlchemy) loads when it is read
    from sqlalchemy.engine import Engine

    from procedures.io.recording.reader import Session
    from station.services.config import StationConfig

COUNTER_NAME = "certificate-counter.json"
FOLDER_NAME = "certificates"
_SAFE = re.compile(r"[^A-Za-z0-9._-]+")
CALIBRATION, VERIFICATION, OTHER = "calibration", "verification", "other"  # session_stage


@dataclass(frozen=True)
class Issued:
    report_no: str
    revision: int
    pdf: Path
    json: Path
    index: Path
    content: dict[str, Any]
    earlier: list[str] = field(default_factory=list)  # certificates already made from the same sessions


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


def session_stage(session) -> str:
    """Whether `session` is an as-found CALIBRATION, an as-left VERIFICATION or OTHER: the stage the
    session records (procedures/io/recording/stage.py: the root attribute `stage`, derived for older
    files; an import's stated `--stage`; a sweep of a compensated leg is OTHER)."""
    return {AS_FOUND: CALIBRATION, AS_LEFT: VERIFICATION}.get(stage_of_session(session), OTHER)


def simulated_devices(session) -> list[str]:
    """Why a session's measurement was not of a real item: the simulated rig, or a simulated
    drive or laser in its recorded config ([drive] url / [interferometer] port = "sim")."""
    why = []
    if str(session.attrs.get("rig") or "") == "sim":
        why.append(f"{Path(session.path).name} was recorded on the simulated rig")
    cfg = session.station_config or {}
    if str(session.attrs.get("rig") or "") == "import":
        return why  # measured by other software: the config recorded names no device that measured
    for section, key, what in (("drive", "url", "drive"), ("interferometer", "port", "laser")):
        if str((cfg.get(section) or {}).get(key) or "") == "sim" and not why:
            why.append(f"{Path(session.path).name}: the {what} was simulated ([{section}] {key} = \"sim\")")
    return why


def _changes(before: dict, after: dict) -> list[dict[str, str]]:
    """What changed from one revision's content to the next, field by field (dotted names),
    leaving out what every revision changes. A section added or removed as a whole (the as-left
    stage, the table) is one row; derived blocks (a budget, the per-target rows, the environment)
    are one row each, as "changed", since their every figure follows from the session."""
    skip = {"revision", "issued_utc", "supersedes", "approval", "traceability"}
    whole = {"budget", "targets", "environment", "test_parameters", "material", "notes", "warnings", "statements"}

    def show(v: Any) -> str:
        if v is None:
            return "none"
        if isinstance(v, float):
            return f"{v:.6g}"
        if isinstance(v, dict):
            return f"section of {len(v)} fields" if len(json.dumps(v)) > 70 else json.dumps(v, sort_keys=True)
        if isinstance(v, list):
            return f"{len(v)} entries" if len(json.dumps(v)) > 70 else json.dumps(v)
        return str(v)

    rows: list[dict[str, str]] = []

    def diff(a: Any, b: Any, name: str) -> None:
        if a == b:
            return
        key = name.rsplit(".", 1)[-1]
        if isinstance(a, dict) and isinstance(b, dict) and key not in whole:
            for k in sorted(set(a) | set(b)):
                if not name and k in skip:
                    continue
                diff(a.get(k), b.get(k), f"{name}.{k}" if name else k)
            return
        changed = key in whole and a is not None and b is not None
        rows.append({"field": name, "before": "(changed)" if changed else show(a),
                     "after": "(changed, see below)" if changed else show(b)})

    diff(before, after, "")
    return rows


def _earlier(folder: Path, catalog, found_sha: str, left_sha: str | None, skip_no: str | None) -> list[str]:
    """Certificates already issued from the same sessions, "REPORT revision N (where)": in the
    certificates folder's indexes and in the station's catalog (wherever they were written)."""
    seen: dict[tuple[str, int], str] = {}
    for index_path in sorted(folder.glob("*.index.json")):
        try:
            index = json.loads(index_path.read_text())
            revisions = list(index["revisions"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
        for r in revisions:
            if (isinstance(r, dict) and r.get("as_found_session") == found_sha
                    and (r.get("as_left_session") or None) == (left_sha or None)):
                seen[(str(index.get("report_no")), int(r.get("revision") or 0))] = str(folder / str(r.get("pdf")))
    if catalog is not None and catalog.local.exists():
        from station.catalog.certificates import for_sessions  # noqa: PLC0415

        try:
            for c in for_sessions(catalog.engine, found_sha, left_sha):
                seen.setdefault((c.report_no, c.revision), c.path)
        except Exception:  # noqa: BLE001  a catalog that cannot be read does not stop a certificate
            pass
    return [f"{no} revision {rev} ({where})" for (no, rev), where in sorted(seen.items()) if no != skip_no]


def _register(catalog, cert: dict, pdf_path: Path, pdf_sha: str, json_path: Path) -> None:
    """Index the certificate PDF in the station's catalog (off: nothing); never fails the issue:
    the files are the record and `station catalog sync` / `rebuild` index them later."""
    if catalog is None:
        return
    from station.catalog.certificates import certificate_rec  # noqa: PLC0415

    try:
        catalog.ingest([certificate_rec(cert, pdf_path, pdf_sha, json_path)])
    except Exception as exc:  # noqa: BLE001
        import logging  # noqa: PLC0415

        logging.getLogger(__name__).warning("catalog %s: certificate %s not indexed (%s)", catalog.local, pdf_path, exc)


def issue_certificate(as_found: Session, *, leg: int | None = None, as_left: Session | None = None, table: str | os.PathLike | None = None,
                      lab: dict | None = None, customer: str | None = None, folder: str | os.PathLike,
                      counter_path: str | os.PathLike, revise: str | None = None, reason: str = "",
                      tolerances: dict | None = None, issued_utc: str | None = None,
                      station_id: str = "", table_leg_sha256: str | None = None,
                      customer_contact: str | None = None, authoriser: dict | None = None,
                      prepared_by: str = "", catalog=None, received: str | None = None) -> Issued:
    """Issue a certificate of `leg` from the sessions `as_found` (a calibration) and `as_left` (a
    verification after it), both procedures.io.recording.reader.Session; `table` the compensation
    table pushed (its sha256 is stated); `revise` the report number of a certificate this one
    corrects (`reason` says why; only for the same item: serial and part number). `customer` /
    `customer_contact` None: not given (a revision keeps the previous revision's). `tolerances`
    {type: Tolerance.to_json()} (None: the sessions' recorded ones); `station_id` names the
    issuing station in the report number when the session does not record one;
    `table_leg_sha256` the sha256 of the leg's rows of `table` as its holder stores them
    (station.services.table_jobs.expected_tables), checked against the table the as-left session
    found active. `authoriser` {name, role} who approves ([lab]); `catalog` (station.catalog.store.
    Catalog or None) indexes the PDF and is asked for earlier certificates of the same sessions;
    `received` the date the item was received (None: not given; a revision keeps the previous one).
    The result is a draft until `approve`."""
    folder, counter_path = Path(folder), Path(counter_path)
    leg = pick_leg(as_found, leg)
    if session_stage(as_found) == VERIFICATION:
        raise InputError(f"{as_found.path}: a verification session (as left); a certificate is issued from the leg's "
                         f"as-found calibration session: give that session, with --as-left {Path(as_found.path).name}")
    if session_stage(as_found) == OTHER:
        raise InputError(f"{as_found.path}: a session of no stated stage (an import without --stage, or stage "
                         "other); a certificate is issued from an as-found calibration: re-import it with "
                         "--stage calibration")
    if not as_found.identity.leg(leg).serial:
        raise InputError(f"{as_found.path}: leg {leg} has no serial recorded; a certificate must identify the item "
                         "calibrated: sweep it with --serial LEG=SERIAL (or [legs.N] serial) and certify that session")
    if as_left is not None:
        start_found, start_left = str(as_found.attrs.get("started_utc") or ""), str(as_left.attrs.get("started_utc") or "")
        if start_found and start_left and start_left < start_found:
            raise InputError(f"{as_left.path} was measured ({start_left}) before {as_found.path} ({start_found}): "
                             "the as-left session comes after the as-found calibration")
    item = as_found.identity.leg(leg)
    previous = None
    if revise:
        index = read_index(folder, revise)
        if not reason:
            raise InputError("--revise needs --reason: a corrected certificate says what was corrected")
        last = index["revisions"][-1]
        try:
            previous = json.loads((folder / last["json"]).read_text())
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"{folder / str(last.get('json'))}: cannot read the revision to correct ({exc})") from None
        was = previous.get("item") or {}
        now = {"serial": item.serial, "part_number": item.part_number or "not stated"}
        if (was.get("serial"), was.get("part_number")) != (now["serial"], now["part_number"]):
            raise InputError(f"--revise {revise}: that certificate is of serial {was.get('serial')} part number "
                             f"{was.get('part_number')}, these sessions measured serial {now['serial']} part number "
                             f"{now['part_number']}; a revision corrects the same item: issue a new certificate "
                             "(without --revise)")
    found = session_decisions(as_found, tolerances=tolerances, stage="as_found")
    left = session_decisions(as_left, tolerances=tolerances, stage="as_left") if as_left is not None else None
    left_leg = _as_left_leg(as_found, as_left, leg) if left is not None else None
    folder.mkdir(parents=True, exist_ok=True)
    issued_utc = issued_utc or certificate.now_utc()
    # a correction made in an earlier revision stays unless this one corrects it again
    if previous is not None:
        if customer is None:
            customer = None if previous.get("customer") in (None, "not stated") else previous["customer"]
        if received is None:
            received = None if (previous.get("item") or {}).get("received") in (None, "not stated") else \
                previous["item"]["received"]
        if customer_contact is None:
            customer_contact = None if previous.get("customer_contact") in (None, "not stated") else \
                previous["customer_contact"]
    table_rec = table_record(table)
    if table_rec is None and previous is not None and previous.get("compensation_table"):
        table_rec = dict(previous["compensation_table"])
    if table_rec is not None and table_leg_sha256:
        table_rec["leg_rows_sha256"] = table_leg_sha256
        if as_left is not None:
            active = _active_table_sha256(as_left, left_leg)
            table_rec["active_as_left_sha256"] = active
            table_rec["matches_as_left"] = active == table_leg_sha256 if active else None
    simulated = simulated_devices(as_found) + (simulated_devices(as_left) if as_left is not None else [])
    instrument = _instrument(as_found)
    cal_cert = ((as_found.station_config or {}).get("metrology") or {}).get("calibration_certificate")
    if cal_cert:
        instrument = {**(instrument or {}), "certificate": cal_cert}

    def build(report_no: str, revision: int, supersedes: dict | None) -> dict:
        try:
            cert = certificate.content(found, leg, report_no=report_no, revision=revision, issued_utc=issued_utc,
                                       lab=lab or {}, customer=customer or "", as_left=left, table=table_rec,
                                       supersedes=supersedes, instrument=instrument, as_left_leg=left_leg,
                                       customer_contact=customer_contact or "", simulated=simulated,
                                       authoriser=authoriser, prepared_by=prepared_by, received=received or "")
        except (KeyError, ValueError) as exc:
            raise InputError(f"{as_found.path}: {exc}") from None
        cert["as_found"]["kind"] = "as-found calibration"
        if cert["as_left"] is not None:
            cert["as_left"]["kind"] = ("as-left verification" if session_stage(as_left) == VERIFICATION else
                                       "as left: a sweep recorded after the calibration (not a `station verify`)")
        return cert

    if revise:
        last = index["revisions"][-1]
        report_no, revision = revise, int(last["revision"]) + 1
        supersedes = {"report_no": revise, "revision": last["revision"], "sha256_pdf": last["sha256_pdf"],
                      "reason": reason}
        cert = build(report_no, revision, supersedes)
        supersedes["changes"] = _changes(previous, cert)
    else:
        build("pending", 1, None)  # everything checked before a number is used up
        station = as_found.identity.station.id or station_id or "station"
        report_no = next_report_no(counter_path, station, _dt.date.fromisoformat(issued_utc[:10]))
        index, revision = {"report_no": report_no, "revisions": []}, 1
        cert = build(report_no, revision, None)
    earlier = _earlier(folder, catalog, cert["as_found"]["session_sha256"],
                       (cert["as_left"] or {}).get("session_sha256"), report_no)
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
        if r["status"] in ("issued", "approved"):
            r.update(status="superseded", superseded_by=revision, superseded_utc=issued_utc, reason=reason)
    pdf_sha = hashlib.sha256(pdf_bytes).hexdigest()
    index["revisions"].append({"revision": revision, "status": "issued", "issued_utc": issued_utc,
                               "pdf": pdf_path.name, "json": json_path.name,
                               "sha256_pdf": pdf_sha, "serial": cert["item"]["serial"],
                               "part_number": cert["item"]["part_number"],
                               "as_found_session": cert["as_found"]["session_sha256"],
                               "as_left_session": (cert["as_left"] or {}).get("session_sha256")})
    index_path = _index_path(folder, report_no)
    write_bytes_atomic(index_path, (json.dumps(index, indent=2) + "\n").encode())
    _register(catalog, cert, pdf_path, pdf_sha, json_path)
    return Issued(report_no, revision, pdf_path, json_path, index_path, cert, earlier)


def find_folder(report_no: str, folder: Path, catalog=None) -> Path:
    """The folder holding certificate `report_no`'s index: `folder`, else where the catalog says
    its PDF was written. InputError when neither knows it."""
    if _index_path(folder, report_no).is_file():
        return folder
    if catalog is not None and catalog.local.exists():
        from station.catalog.certificates import find  # noqa: PLC0415

        for c in find(catalog.engine, report_no):
            where = Path(c.path).parent
            if _index_path(where, report_no).is_file():
                return where
    raise InputError(f"no certificate {report_no} in {folder} nor in the catalog; `station certificates` lists them")


def approve(report_no: str, *, by: str, folder: str | os.PathLike, authoriser: dict, audit_path: str | os.PathLike,
            catalog=None, station_id: str | None = None, approved_utc: str | None = None) -> Issued:
    """Approve the current revision of certificate `report_no`: `by` must be the authoriser the
    config names ([lab] authoriser); the approved document REPORT_rN_approved.pdf/.json is written
    once, read-only, beside the draft (which stays unchanged), recorded in the audit log (action
    "approve") and in the catalog, and the index marks the revision approved."""
    from procedures.compensation.audit import (  # noqa: PLC0415
        AuditEntry, AuditError, AuditLog, AuditRecord, AuditSink, new_id,
    )

    name, role = (authoriser or {}).get("name") or "", (authoriser or {}).get("role") or ""
    if not name:
        raise InputError("no authoriser in the config: set [lab] authoriser (and authoriser_role) to the person who "
                         "approves certificates")
    if by.strip() != name:
        raise InputError(f"--by {by!r}: certificates are approved by the laboratory's authoriser {name!r} ([lab] "
                         "authoriser in the config)")
    folder = find_folder(report_no, Path(folder), catalog)
    index = read_index(folder, report_no)
    last = index["revisions"][-1]
    if last.get("status") == "approved":
        raise InputError(f"certificate {report_no} revision {last['revision']} is already approved by "
                         f"{last.get('approved_by')} ({last.get('approved_utc')}): {folder / last['approved_pdf']}")
    if last.get("status") != "issued":
        raise InputError(f"certificate {report_no} revision {last['revision']} is {last.get('status')}; only the "
                         "current revision is approved")
    draft_json = folder / last["json"]
    try:
        cert = json.loads(draft_json.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{draft_json}: cannot read the certificate ({exc})") from None
    if hashlib.sha256((folder / last["pdf"]).read_bytes()).hexdigest() != last["sha256_pdf"]:
        raise InputError(f"{folder / last['pdf']}: its sha256 is not the one issued; the draft was changed: "
                         "approve nothing, issue a revision")
    approved_utc = approved_utc or certificate.now_utc()
    stem = f"{report_no}_r{last['revision']}_approved"
    pdf_path, json_path = folder / f"{stem}.pdf", folder / f"{stem}.json"
    if pdf_path.exists():
        raise InputError(f"{pdf_path}: exists; an approved certificate is never written twice")
    audit_id = new_id()  # named in the document, so the entry is written once the document is
    cert["approval"].update(status="approved", approved_by=name, approved_role=role, approved_utc=approved_utc,
                            audit_id=audit_id)
    pdf_bytes = certificate.pdf(cert)
    _create_new(pdf_path, pdf_bytes)
    written = [pdf_path]
    try:
        _create_new(json_path, (json.dumps(cert, indent=2, allow_nan=False) + "\n").encode())
        written.append(json_path)
        # through the audit sink, the log's one writer (tests/test_layering.py)
        sink = AuditSink(AuditLog(audit_path, operator=by, station_id=station_id))
        try:
            sink.handle(AuditRecord(AuditEntry(
                "approve", int(cert["item"]["leg"]), "ok",
                f"certificate {report_no} revision {last['revision']} approved by {name}, {role}",
                id=audit_id, time_utc=approved_utc.replace("+00:00", "Z"), leg_serial=cert["item"]["serial"],
                operator=by, details={"report_no": report_no, "revision": last["revision"],
                                      "draft_sha256_pdf": last["sha256_pdf"], "role": role, "pdf": str(pdf_path),
                                      "sha256_pdf": hashlib.sha256(pdf_bytes).hexdigest()})))
        except AuditError as exc:
            raise InputError(f"{str(exc).split(': ', 1)[-1]}: the approval could not be recorded; nothing was "
                             "approved") from None
    except BaseException:  # no approved document without its audit entry
        for p in written:
            os.chmod(p, 0o644)
            p.unlink()
        raise
    sha = hashlib.sha256(pdf_bytes).hexdigest()
    last.update(status="approved", approved_by=name, approved_role=role, approved_utc=approved_utc,
                approved_pdf=pdf_path.name, approved_json=json_path.name, approved_sha256_pdf=sha, audit_id=audit_id)
    index_path = _index_path(folder, report_no)
    write_bytes_atomic(index_path, (json.dumps(index, indent=2) + "\n").encode())
    _register(catalog, cert, pdf_path, sha, json_path)
    return Issued(report_no, int(last["revision"]), pdf_path, json_path, index_path, cert)


# -- the certificate jobs as every front end asks for them (issue 32 part 1) ----------------------

@dataclass
class ApproveRequest:
    """Approve the current revision of certificate `report_no` by `by` (the [lab] authoriser);
    `out`: the certificates folder (None: <recordings_dir>/certificates)."""

    report_no: str | None
    by: str | None
    out: str | os.PathLike | None = None


def approve_certificate(request: ApproveRequest, cfg: StationConfig) -> Issued:
    """`approve` with what the station config `cfg` says: the folder, the authoriser, the audit
    log and the catalog the approval is recorded in."""
    from station.catalog.writer import catalog_for  # noqa: PLC0415
    from station.services.config import AUDIT_NAME  # noqa: PLC0415

    if not request.report_no or not request.by:
        raise InputError("usage: station certificate approve REPORT_NO --by NAME (the [lab] authoriser)")
    folder = Path(request.out) if request.out else Path(cfg.recordings_dir) / FOLDER_NAME
    return approve(request.report_no, by=request.by, folder=folder,
                   authoriser={"name": cfg.lab.authoriser, "role": cfg.lab.authoriser_role},
                   audit_path=Path(cfg.recordings_dir) / AUDIT_NAME, catalog=catalog_for(cfg),
                   station_id=cfg.station_id)


@dataclass
class CertificateRequest:
    """Issue a certificate (a DRAFT until approved) of leg `leg` (None: the session's only one)
    from the as-found session `session`, the as-left session `as_left` and the table `table`
    (paths; None: none). `out`: the certificates folder (None: <recordings_dir>/certificates);
    `customer`/`customer_contact`: None = the config's (a revision keeps the earlier one's);
    `received`: YYYY-MM-DD; `revise`: the report number of which to issue the next revision, with
    `reason`; `use_config_tolerances`: the config's [tolerances] instead of the session's."""

    session: str | os.PathLike
    as_left: str | os.PathLike | None = None
    table: str | os.PathLike | None = None
    leg: int | None = None
    out: str | os.PathLike | None = None
    customer: str | None = None
    customer_contact: str | None = None
    received: str | None = None
    revise: str | None = None
    reason: str = ""
    use_config_tolerances: bool = False


@dataclass
class PreparedCertificate(OfflineJob):
    """A certificate whose sessions were read and inputs checked; `run` issues it."""

    kwargs: dict[str, Any]
    as_found: Session

    def run(self, sinks=(), control=None):
        from station.services.job import JobOutcome  # noqa: PLC0415

        issued = issue_certificate(self.as_found, **self.kwargs)
        return JobOutcome("done", outputs=[Path(issued.pdf), Path(issued.json)], lines=issue_lines(issued),
                          data=issued)


def prepare_certificate(request: CertificateRequest, cfg: StationConfig) -> PreparedCertificate:
    """Read the sessions, pick the leg, hash the leg's rows of the table as its drive holds them,
    and check the received date (InputError naming what to give)."""
    from procedures.io.recording.reader import read_session  # noqa: PLC0415
    from station.catalog.writer import catalog_for  # noqa: PLC0415

    r = request
    as_found = read_session(Path(r.session))
    as_left = read_session(Path(r.as_left)) if r.as_left else None
    tolerances = {k: t.to_json() for k, t in cfg.tolerances.items()} if r.use_config_tolerances else None
    folder = Path(r.out) if r.out else Path(cfg.recordings_dir) / FOLDER_NAME
    lab = {"name": cfg.lab.name, "address": cfg.lab.address, "accreditation": cfg.lab.accreditation}
    leg = pick_leg(as_found, r.leg)
    leg_sha = None
    if r.table:  # the leg's rows as its drive (or the station) holds them: compared with the as-left table
        from station.services.table_jobs import expected_tables  # noqa: PLC0415
        from station.services.wiring import leg_table_spec  # noqa: PLC0415

        leg_sha = expected_tables(r.table, (leg,), leg_table_spec(cfg, leg))[leg]
    # a revision keeps the customer an earlier revision corrected unless given again
    customer = r.customer if r.customer is not None else (None if r.revise else cfg.lab.customer)
    contact = r.customer_contact if r.customer_contact is not None else (
        None if r.revise else cfg.lab.customer_contact)
    received = None
    if r.received is not None:
        try:
            received = _dt.date.fromisoformat(r.received).isoformat()
        except ValueError:
            raise InputError(f"--received {r.received!r}: give the date the item was received as YYYY-MM-DD") from None
    kwargs = dict(leg=leg, as_left=as_left, table=r.table, lab=lab, customer=customer, folder=folder,
                  counter_path=Path(cfg.recordings_dir) / COUNTER_NAME, revise=r.revise, reason=r.reason,
                  tolerances=tolerances, station_id=cfg.station_id, table_leg_sha256=leg_sha,
                  customer_contact=contact, authoriser={"name": cfg.lab.authoriser, "role": cfg.lab.authoriser_role},
                  prepared_by=cfg.operator, catalog=catalog_for(cfg), received=received)
    return PreparedCertificate(kwargs, as_found, lines=[f"certificate of leg {leg} from {r.session}"])


def issue_lines(issued: Issued) -> list[str]:
    """What to tell the user about a certificate just issued: its number and verdicts, every
    warning it carries, the files written and how to approve it."""
    c = issued.content
    lines = [f"certificate {issued.report_no} revision {issued.revision} (DRAFT until approved): leg {c['item']['leg']} "
             f"serial {c['item']['serial']}, as found {c['as_found']['overall']}"
             + (f", as left {c['as_left']['overall']}" if c["as_left"] else "")]
    if issued.earlier:
        lines.append(f"warning: these sessions are already certified: {'; '.join(issued.earlier)}; this is another "
                     f"number for the same measurement (a correction is `--revise {issued.earlier[0].split(' ')[0]} "
                     "--reason ...`)")
    if c.get("simulated"):
        lines.append("warning: SIMULATION: " + "; ".join(c["simulated"]) + "; the certificate says so on every page "
                     "and states no accreditation")
    if not c["traceability"]["traceable"]:
        lines.append("warning: " + c["traceability"]["statement"].split(". The results")[0] + "; the certificate says "
                     "NOT TRACEABLE")
    if (c["compensation_table"] or {}).get("matches_as_left") is False:
        lines.append("warning: the table active in the as-left session is NOT the --table given; the certificate says so")
    if c["supersedes"]:
        lines.append(f"supersedes revision {c['supersedes']['revision']} (kept; marked superseded in {issued.index}); "
                     f"{len(c['supersedes'].get('changes') or [])} field(s) changed")
    lines += [f"wrote {issued.pdf}", f"wrote {issued.json}", f"index {issued.index}",
              f"approve it: station certificate approve {issued.report_no} --by NAME"]
    return lines


@dataclass
class CatalogSources:
    """What the catalog gives a certificate of one leg: its as-found session, as-left session and
    table (paths; those given win over the catalog's) and the leg of the as-found session."""

    session: str
    as_left: str | None
    table: str | None
    leg: int | None


def sources_from_catalog(engine: Engine, where: str, serial: str, *, as_left: str | None = None,
                         table: str | None = None, say: Callable[[str], None] | None = None) -> CatalogSources:
    """The sources of leg `serial` in the catalog `engine` (described by `where`): the last
    calibration, the verification after it and the last table pushed after it; `say(line)` is
    told each (and the catalog). InputError when the catalog lists a file that is missing."""
    from station.catalog.certificate_sources import certificate_sources  # noqa: PLC0415

    say = say or (lambda line: None)
    found = certificate_sources(engine, serial)
    say(where)
    given = {"as left": as_left, "table": table}  # given on the command line: those win
    picked = [("as found", found.as_found, "calibration session", "no calibration"),
              ("as left", found.as_left, "verification session", "no verification session after the calibration"),
              ("table", found.table, "last table pushed", "no table pushed after the calibration is indexed")]
    for label, src, what, none in picked:
        if given.get(label):
            say(f"{label}: {given[label]} (given)")
        elif src is None:
            say(f"{label}: none ({none})")
        else:
            say(f"{label}: {src.path} ({what}, {src.time_utc}, sha256 {(src.sha256 or '?')[:16]})")
            if not Path(src.path).is_file():
                raise InputError(f"{src.path}: the catalog lists this {what} of leg {serial} but the file is "
                                 "missing; restore it, or re-index with `station catalog check` and `station catalog "
                                 "rebuild DIR`")
    if found.table is None and found.pushed_table_sha256 and not table:
        say(f"note: a table (sha256 {found.pushed_table_sha256[:16]}) was pushed after the calibration but its "
            "file is not in the catalog; give it with --table to state it")
    return CatalogSources(found.as_found.path, as_left or (found.as_left.path if found.as_left else None),
                          table or (found.table.path if found.table else None), found.as_found.leg)
