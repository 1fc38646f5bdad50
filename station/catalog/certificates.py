"""Certificates in the catalog (docs/certificate.md): one record of kind "certificate" per PDF
`station certificate` writes (a draft revision, and the approved document `approve` makes),
keyed by the PDF's sha256 like every other file record, wherever the PDF was written (`--out`).
The certificate's JSON beside the PDF holds everything the record says, so `station catalog
rebuild` finds them again (`certificate_rec_of_json`).

No leg rows: a certificate is not a measurement, and history, legs and charts count
measurements; the serial is in the record's summary and `issued` filters on it.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from station.catalog.models import Record
from station.catalog.readers import Rec, sha256_of

KIND = "certificate"


def certificate_rec(cert: dict[str, Any], pdf_path: str | os.PathLike, pdf_sha256: str,
                    json_path: str | os.PathLike) -> Rec:
    """The record of one certificate PDF from its content (procedures.reporting.certificate.content)."""
    appr = cert.get("approval") or {}
    approved = appr.get("status") == "approved"
    rec = Rec(kind=KIND, key=pdf_sha256, time_utc=_utc(appr["approved_utc"] if approved else cert["issued_utc"]),
              station_id=(cert.get("place") or {}).get("station") or None,
              operator=(appr.get("approved_by") if approved else appr.get("prepared_by")) or None,
              outcome="approved" if approved else "draft", path=str(Path(pdf_path).resolve()), sha256=pdf_sha256,
              source_sha256=(cert.get("as_found") or {}).get("session_sha256"))
    item = cert.get("item") or {}
    rec.summary = {"report_no": cert["report_no"], "revision": int(cert["revision"]), "status": rec.outcome,
                   "serial": item.get("serial"), "part_number": item.get("part_number"),
                   "leg_type": item.get("leg_type"), "customer": cert.get("customer"),
                   "issued_utc": cert["issued_utc"], "json": str(Path(json_path).resolve()),
                   "as_found_session": (cert.get("as_found") or {}).get("session_sha256"),
                   "as_left_session": (cert.get("as_left") or {}).get("session_sha256"),
                   "approved_by": appr.get("approved_by") if approved else None,
                   "approved_utc": appr.get("approved_utc") if approved else None,
                   "simulated": bool(cert.get("simulated"))}
    return rec


def certificate_rec_of_json(path: str | os.PathLike) -> Rec | None:
    """The record of the certificate whose JSON is `path` (its PDF beside it), None when `path`
    is not a certificate's JSON or its PDF is gone (for `station catalog rebuild`)."""
    p = Path(path)
    try:
        cert = json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    from procedures.reporting.certificate import TITLE  # noqa: PLC0415

    if not isinstance(cert, dict) or cert.get("title") != TITLE or "report_no" not in cert:
        return None
    pdf = p.with_suffix(".pdf")
    if not pdf.is_file():
        return None
    return certificate_rec(cert, pdf, sha256_of(pdf), p)


def _utc(text: str) -> str:
    """An ISO time as the catalog keeps times: "YYYY-MM-DDTHH:MM:SSZ"."""
    return str(text).replace("+00:00", "Z")


@dataclass(frozen=True)
class Listed:
    report_no: str
    revision: int
    status: str  # draft / approved / superseded
    serial: str
    issued_utc: str
    approved_by: str | None
    approved_utc: str | None
    station_id: str | None
    path: str
    simulated: bool
    as_found_session: str | None
    as_left_session: str | None
    sha256: str | None = None


def issued(engine: Engine, serial: str | None = None) -> list[Listed]:
    """Every certificate revision in the catalog (of leg `serial`), by number and revision: a
    revision with an approved document is "approved" (its approved PDF listed), an older revision
    of a number "superseded", else "draft"."""
    with engine.connect() as conn:
        rows = conn.execute(sa.select(Record.path, Record.summary, Record.station_id, Record.sha256)
                            .where(Record.kind == KIND).order_by(Record.time_utc, Record.uid)).all()
    by_rev: dict[tuple[str, int], dict[str, Any]] = {}
    latest: dict[str, int] = {}
    for path, summary, station, sha in rows:
        s = summary or {}
        if serial is not None and s.get("serial") != serial:
            continue
        key = (str(s.get("report_no")), int(s.get("revision") or 0))
        latest[key[0]] = max(latest.get(key[0], 0), key[1])
        have = by_rev.get(key)
        if have is None or s.get("status") == "approved":  # the approved document stands for its revision
            by_rev[key] = {"summary": s, "path": path, "station": station, "sha256": sha}
    out = []
    for (no, rev), d in sorted(by_rev.items()):
        s = d["summary"]
        status = "superseded" if rev < latest[no] else s.get("status") or "draft"
        out.append(Listed(no, rev, status, str(s.get("serial")), str(s.get("issued_utc")), s.get("approved_by"),
                          s.get("approved_utc"), d["station"], d["path"] or "", bool(s.get("simulated")),
                          s.get("as_found_session"), s.get("as_left_session"), d["sha256"]))
    return out


def for_sessions(engine: Engine, as_found_sha256: str, as_left_sha256: str | None) -> list[Listed]:
    """The certificates already made from the same as-found (and as-left) sessions."""
    return [c for c in issued(engine) if c.as_found_session == as_found_sha256
            and (c.as_left_session or None) == (as_left_sha256 or None)]


def find(engine: Engine, report_no: str) -> list[Listed]:
    """The revisions of certificate `report_no` in the catalog."""
    return [c for c in issued(engine) if c.report_no == report_no]
