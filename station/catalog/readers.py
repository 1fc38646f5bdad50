"""What the catalog knows of a file: one `Rec` per session (.h5), model (.json), table (.csv),
report folder and audit entry, read from the file alone, so a record written as the station
works and one rebuilt from the files later are equal.

Identity comes from the file (station.catalog.identity_reader); a record that names no station is
given `default_station` (the station whose catalog indexes it, `[station] id`). A model
or report that names no leg serials takes those of the session it was made from, when the
catalog already holds it (`serials_of_source`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterator

from procedures.io.recording import stage as stages
from procedures.reporting import evaluation
from station.catalog import identity_reader as ident
from station.catalog.models import FIGURES

SerialLookup = Callable[[str], dict[int, str]]


@dataclass
class Rec:
    """One catalog record and the legs it concerns (see station.catalog.models)."""

    kind: str
    key: str
    time_utc: str
    station_id: str | None = None
    station_host: str | None = None
    operator: str | None = None
    software_version: str | None = None
    instrument: dict | None = None
    outcome: str | None = None
    path: str | None = None
    sha256: str | None = None
    source_sha256: str | None = None
    summary: dict = field(default_factory=dict)
    stage: str | None = None  # procedures/io/recording/stage.py; None for models, tables, reports
    supersedes: list[str] | None = None  # uids of records this file replaced at its path (store.write_recs)
    legs: dict[int, dict] = field(default_factory=dict)
    leg_info: dict[str, dict] = field(default_factory=dict)  # serial -> part_number, leg_type, screw_lot

    @property
    def uid(self) -> str:
        return f"{self.kind}:{self.key}"

    @property
    def stage_or_default(self) -> str | None:
        """`stage`, or for a record made without one (through the API, not from a file) the rule
        catalog revision 0003 classified older rows by: audit kinds by kind, a session by the plan
        kind its summary keeps (verification: as left; import: other; else as found)."""
        if self.stage is not None:
            return self.stage
        if self.kind in stages.AUDIT_STAGES:
            return stages.AUDIT_STAGES[self.kind]
        if self.kind == "session":
            plan_kind = (self.summary or {}).get("plan_kind")
            return {"verification": stages.AS_LEFT, "import": stages.OTHER}.get(plan_kind, stages.AS_FOUND)
        return None


def sha256_of(path: str | os.PathLike) -> str:
    from procedures.io.recording.reader import file_sha256

    return file_sha256(path)


def _abs(path: str | os.PathLike) -> str:
    return str(Path(path).resolve())


def _finite(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        v = float(v)
    except OverflowError:  # a JSON integer beyond any float
        return None
    return v if math.isfinite(v) else None


def _mtime_utc(path: str | os.PathLike) -> str:
    return datetime.fromtimestamp(os.stat(path).st_mtime, timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def utc_text(value: Any, fallback: str) -> str:
    """A UTC time as the files write it, if it is one; else `fallback`."""
    t = ident.text(value)
    if t is None:
        return fallback
    try:
        datetime.fromisoformat(t.replace("Z", "+00:00"))
    except ValueError:
        return fallback
    return t[:32]


def _apply_identity(rec: Rec, identity: dict) -> None:
    rec.station_id, rec.station_host = ident.station_of(identity)
    rec.operator = ident.text(identity.get("operator")) or rec.operator
    rec.software_version = ident.text(identity.get("software_version")) or rec.software_version
    rec.instrument = ident.instrument_of(identity)
    for leg, info in ident.legs_of(identity).items():
        row = rec.legs.setdefault(leg, {})
        row["leg_serial"] = info["serial"]
        if info.get("drive"):
            row.setdefault("drive", info["drive"])
        rec.leg_info[info["serial"]] = {k: info[k] for k in ("part_number", "leg_type", "screw_lot")}


def iso_figures(values: Any) -> dict:
    """Columns of record_legs from an ISO 230-2 `values` dict ({"E": {"value_um", "U_um"}, ...} or
    {"E": number}) plus every value in `figures`."""
    out: dict[str, Any] = {}
    values = values if isinstance(values, dict) else {}
    figures: dict[str, Any] = {}
    for name, v in values.items():
        if isinstance(v, dict):
            value, u = _finite(v.get("value_um")), _finite(v.get("U_um"))
        else:
            value, u = _finite(v), None
        figures[str(name)[:16]] = {"value_um": value, "U_um": u}
    for name in FIGURES:
        f = figures.get(name) or {}
        out[f"{name}_um"], out[f"{name}_U_um"] = f.get("value_um"), f.get("U_um")
    out["figures"] = figures
    return out


# -- sessions ---------------------------------------------------------------------------------------

def session_identity(path: str | os.PathLike) -> dict:
    """The identity of a session file as JSON ({} for a file without one, schema 1.0, or when
    unreadable), read by the sessions' one reader (procedures.io.recording.reader.read_identity),
    not parsed again here."""
    from procedures.io.recording.reader import read_identity

    try:
        identity = read_identity(path)
    except Exception:  # an unreadable file names no leg: the caller's message says what is missing
        return {}
    return identity.to_json() if identity.recorded else {}


def session_rec(path: str | os.PathLike) -> Rec:
    """A session file's record: identity, times, outcome, ISO 230-2 values with U per leg.
    InputError (naming the file) when it is not a readable session."""
    from procedures.io.recording.reader import read_session

    session = read_session(path)
    attrs = session.attrs
    rec = Rec(kind="session", key=session.sha256, time_utc=utc_text(attrs.get("started_utc"), _mtime_utc(path)),
              operator=ident.text(attrs.get("operator")), software_version=ident.text(attrs.get("software_version")),
              outcome=session.outcome, path=_abs(path), sha256=session.sha256,
              stage=session.stage)  # recorded in the file (schema 1.2) or derived from it (older files)
    rec.summary = {"session_id": ident.text(attrs.get("session_id")), "rig": ident.text(attrs.get("rig")),
                   "ended_utc": ident.text(attrs.get("ended_utc")), "points": int(session.points.size),
                   "schema_version": session.schema_version,
                   # "verification" for an as-left sweep (`station verify`): certificates by serial tell them apart
                   "plan_kind": ident.text((session.plan or {}).get("kind"))}
    # the one evaluation (procedures.reporting.evaluation, what the report and the certificate
    # state): values with U, per-target means with U (the web's per-target E_n), and the verdict
    # of each leg at the session's stage against the tolerances the session recorded (revision
    # 0004: the web's decision filter reads the column)
    ev = None
    if session.points.size:
        try:
            ev = evaluation.evaluate_session(session)
        except Exception as exc:  # a session too short for ISO 230-2 is still a record
            rec.summary["iso230_not_computed"] = str(exc)[:200]
    for leg in session.legs:
        rec.legs[leg] = {**iso_figures(evaluation.leg_values(ev, leg) if ev else None),
                         "drive": ident.text(session.devices.get(f"leg{leg}_drive"))}
        verdict = evaluation.leg_verdict(ev, leg) if ev else None
        if verdict is not None:
            rec.legs[leg]["decision"] = verdict
    if ev:
        rec.summary["targets"] = {str(leg): evaluation.leg_targets(ev, leg) for leg in session.legs}
    # the identity read_session parsed (procedures.io.recording.identity), not a second parse of the file
    _apply_identity(rec, session.identity.to_json() if session.identity.recorded else {})
    if rec.instrument is None:  # a 1.0 session: the instrument its config named ([metrology])
        metrology = (session.station_config or {}).get("metrology")
        metrology = metrology if isinstance(metrology, dict) else {}
        serial = ident.text(metrology.get("serial"))
        if serial:
            rec.instrument = {"serial": serial, "model": ident.text(metrology.get("model")), "calibration_due": None,
                              "calibrated_on": ident.text(metrology.get("calibration_date"))}
    return rec


def decide_legs(rec: Rec, tolerances: dict) -> Rec:
    """Set each leg row's `decision` of session record `rec`: the ISO 14253-1 overall verdict of
    its ISO 230-2 values with U (procedures.reporting.decision.decide_leg, the function the report,
    the certificate and the web use) against `tolerances` ({type: Tolerance}) at the record's stage
    (as-left limits for an as-left verification, else as found). A leg whose type has no
    tolerance there is left undecided (None): the web decides it against its own config."""
    from procedures.reporting import decision

    stage = decision.STAGES[1] if rec.stage_or_default == stages.AS_LEFT else decision.STAGES[0]
    for row in rec.legs.values():
        info = rec.leg_info.get(row.get("leg_serial") or "", {})
        leg_type = info.get("leg_type")
        if rec.kind != "session" or not leg_type or leg_type not in tolerances:
            continue
        values = {n: {"value_um": row.get(f"{n}_um"), "U_um": row.get(f"{n}_U_um")} for n in FIGURES}
        row["decision"] = decision.decide_leg(values, {}, leg_type, tolerances, stage)["overall"]
    return rec


# -- models, tables, reports ------------------------------------------------------------------------

def _json_file(path: str | os.PathLike) -> Any:
    try:
        return json.loads(Path(path).read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return None


def model_rec(path: str | os.PathLike, serials_of_source: SerialLookup | None = None) -> Rec | None:
    """A model file's record (None when the file is not a leg-error model)."""
    doc = _json_file(path)
    if not isinstance(doc, dict) or doc.get("format") != "station-leg-error-model":
        return None
    return model_rec_of(doc, sha256_of(path), _abs(path), _mtime_utc(path), serials_of_source)


def model_rec_of(doc: dict, sha: str, path: str, fallback_time: str,
                 serials_of_source: SerialLookup | None = None) -> Rec:
    source = doc.get("source") if isinstance(doc.get("source"), dict) else {}
    rec = Rec(kind="model", key=sha, time_utc=utc_text(doc.get("created_utc"), fallback_time), path=path, sha256=sha,
              source_sha256=ident.text(source.get("sha256")), outcome="ok")
    rec.summary = {"method": ident.text(doc.get("method"))}
    legs = doc.get("legs") if isinstance(doc.get("legs"), dict) else {}
    for key, value in legs.items():
        leg = _leg_number(key)
        if leg is None:
            continue
        stats = value.get("stats") if isinstance(value, dict) and isinstance(value.get("stats"), dict) else {}
        rec.legs[leg] = {"figures": {k: _finite(stats.get(k)) for k in
                                     ("heldout_rms_um", "noise_floor_um", "heldout_ratio", "range_before_um")}}
    _fill_from_source(rec, serials_of_source)
    _apply_identity(rec, ident.parse_identity(doc.get("identity")))
    return rec


def _leg_number(key: Any) -> int | None:
    """A leg number 1..99 from a JSON key, else None."""
    try:
        leg = int(key)
    except (TypeError, ValueError):
        return None
    return leg if 1 <= leg <= 99 else None


def _fill_from_source(rec: Rec, serials_of_source: SerialLookup | None) -> None:
    if rec.source_sha256 and serials_of_source is not None:
        for leg, serial in serials_of_source(rec.source_sha256).items():
            if leg in rec.legs and serial:
                rec.legs[leg].setdefault("leg_serial", serial)


TABLE_HEADER = "leg,position_mm,error_fwd_um,error_rev_um"


def table_rec(path: str | os.PathLike) -> Rec | None:
    """A table CSV's record (None when the file is not a station table): rows and largest
    correction per leg, serials from `# leg_serial:` lines."""
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    lines = text.splitlines()
    body = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if not body or body[0].strip().replace(" ", "") != TABLE_HEADER:
        return None
    sha = sha256_of(path)
    rec = Rec(kind="table", key=sha, time_utc=_mtime_utc(path), path=_abs(path), sha256=sha, outcome="ok")
    per_leg, common = ident.table_serials(lines)
    for row in body[1:]:
        cells = row.split(",")
        try:
            leg = int(cells[0])
            worst = max(abs(float(cells[2])), abs(float(cells[3])))
        except (ValueError, IndexError):
            continue
        if not 1 <= leg <= 99 or not math.isfinite(worst):
            continue
        entry = rec.legs.setdefault(leg, {"figures": {"points": 0, "max_correction_um": 0.0}})
        entry["figures"]["points"] += 1
        entry["figures"]["max_correction_um"] = max(entry["figures"]["max_correction_um"], worst)
    for leg, entry in rec.legs.items():
        serial = per_leg.get(leg) or common
        if serial:
            entry["leg_serial"] = serial
    return rec


REPORT_FILE = "iso230-2.json"


def report_rec(folder: str | os.PathLike, serials_of_source: SerialLookup | None = None) -> Rec | None:
    """A report folder's record (None without a readable iso230-2.json): its ISO 230-2 values with U."""
    path = Path(folder) / REPORT_FILE
    doc = _json_file(path)
    if not isinstance(doc, dict) or not isinstance(doc.get("legs"), dict):
        return None
    sha = sha256_of(path)
    ident_block = doc.get("identification") if isinstance(doc.get("identification"), dict) else {}
    source = ident_block.get("source") if isinstance(ident_block.get("source"), dict) else {}
    rec = Rec(kind="report", key=sha, time_utc=_mtime_utc(path), path=_abs(folder), sha256=sha,
              source_sha256=ident.text(source.get("sha256")), outcome="ok")
    for key, value in doc["legs"].items():
        leg = _leg_number(key)
        if leg is not None and isinstance(value, dict):
            rec.legs[leg] = iso_figures(value.get("values"))
    _fill_from_source(rec, serials_of_source)
    _apply_identity(rec, ident.parse_identity(doc.get("identity")))
    return rec


# -- audit entries ----------------------------------------------------------------------------------

AUDIT_KINDS = {"push": "push", "verify": "verification", "rollback": "rollback"}
AUDIT_STAGES_OF_KIND = stages.AUDIT_STAGES


def audit_rec(d: Any, log_path: str | os.PathLike) -> Rec | None:
    """The record of one audit entry (its parsed JSON line), keyed by the entry's id (None for a
    line that is not an entry, has no id or an unknown action)."""
    from procedures.compensation.audit import AuditEntry

    try:
        entry = AuditEntry.from_json(d)
    except (ValueError, TypeError, OverflowError):
        return None
    kind = AUDIT_KINDS.get(entry.action)
    if kind is None or not ident.text(entry.id):
        return None
    details = entry.details if isinstance(entry.details, dict) else {}
    source = entry.source if isinstance(entry.source, dict) else {}
    after = details.get("after") if isinstance(details.get("after"), dict) else {}
    rec = Rec(kind=kind, key=ident.text(entry.id), time_utc=utc_text(entry.time_utc, "1970-01-01T00:00:00Z"),
              operator=ident.text(entry.operator), outcome=ident.text(entry.outcome), path=_abs(log_path),
              sha256=ident.text(source.get("sha256")) or ident.text(details.get("session_sha256")),
              station_id=ident.text(d.get("station_id")), station_host=ident.text(entry.host),
              stage=AUDIT_STAGES_OF_KIND[kind])
    rec.summary = {"op_id": ident.text(entry.op_id), "message": (ident.text(entry.message) or "")[:500],
                   "bank": entry.bank if isinstance(entry.bank, int) and not isinstance(entry.bank, bool) else None,
                   "drive_url": ident.text(entry.drive_url)}
    row: dict[str, Any] = {"drive": ident.text(entry.drive), "table_sha256": ident.text(entry.table_sha256)}
    if kind == "verification":
        row.update(iso_figures(after.get("iso230")))
        row["verification_ratio"] = _finite(details.get("ratio"))
    serial = ident.text(d.get("leg_serial"))
    if serial:
        row["leg_serial"] = serial
    if 1 <= entry.leg <= 99:
        rec.legs[entry.leg] = row
    return rec


def audit_recs(log_path: str | os.PathLike) -> Iterator[Rec]:
    """Records of every entry of an audit log (lines that are not entries are skipped: the log
    itself reports them)."""
    try:
        raw = Path(log_path).read_bytes()
    except OSError:
        return
    for line in raw.split(b"\n"):
        if not line.strip():
            continue
        try:
            d = json.loads(line.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError):
            continue
        rec = audit_rec(d, log_path) if isinstance(d, dict) else None
        if rec is not None:
            yield rec
