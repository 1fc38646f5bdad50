"""The interchange-CSV jobs (issue 32 part 1, one shape for every job): `station export` and the
Results page's `e` fill an `ExportRequest`, `station import` an `ImportRequest`; `prepare_*` makes
the output check and every refusal that needs no reading; `run` writes and says what it did."""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.vocabulary import InputError
from station import __version__
from station.services.job import JobOutcome, OfflineJob

if TYPE_CHECKING:  # annotations only: a request and its refusal load nothing heavy
    from procedures.io.import_map import ImportMap
    from procedures.io.ranges import PointLimits
    from procedures.io.recording.reader import Session
    from station.services.config import StationConfig

# -- export: a session file -> the interchange CSV --------------------------------------------------

@dataclass
class ExportRequest:
    """Write the points of the session file `session` to the CSV `out` (replaced only with
    `force`; its folder made with `make_parents`, as the UI's Results page writes beside a sample)."""

    session: Path
    out: Path
    force: bool = False
    make_parents: bool = False


@dataclass
class PreparedExport(OfflineJob):
    request: ExportRequest

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.io.csv_io import export_csv
        from station.services.report_jobs import export_lines

        r = self.request
        summary = export_csv(Path(r.session), Path(r.out), overwrite=r.force)
        return JobOutcome("done", outputs=[Path(summary.path)], lines=export_lines(summary), data=summary)


def prepare_export(request: ExportRequest, cfg: StationConfig | None = None) -> PreparedExport:
    """Refuse an existing output without force (procedures/io/outputs.py)."""
    from procedures.io.outputs import check_output_file

    check_output_file(request.out, force=request.force, make_parents=request.make_parents)
    return PreparedExport(request, lines=[f"export {request.session} -> {request.out}"])


# -- import: an interchange CSV (or another layout through a map) -> a session file ----------------

@dataclass
class ImportRequest:
    """Convert the CSV `csv` to the session file `out` (replaced only with `force`). `legs`: the
    legs it may hold ("1-6"); `map`: a mapping TOML for another software's layout; `profile`: the
    drive profile whose soft limits bound target_mm (None: built in); identity: `serial` (a list of
    [LEG=]SERIAL), `part_number`, `leg_type`, `screw_lot`, `station`, `stage`, `measured`; `config`:
    a station TOML recorded in the session ([legs.N], [station] id, [metrology], [tolerances])."""

    csv: Path
    out: Path
    operator: str = ""
    force: bool = False
    legs: str = "1-6"
    map: Path | None = None
    accept_implausible: bool = False
    profile: Path | None = None
    serial: list[str] | None = None
    part_number: str | None = None
    leg_type: str | None = None
    screw_lot: str | None = None
    station: str | None = None
    stage: str | None = None
    measured: str | None = None
    config: Path | None = None


def import_limits(legs: str = "1-6", profile: str | None = None):
    """The physical ranges of an import (procedures.io.ranges.PointLimits): the legs given, the
    drive profile's soft limits."""
    from procedures.acquisition.plans import parse_legs
    from procedures.io.ranges import PointLimits
    from station.services.wiring import drive_soft_limits

    return PointLimits(legs=parse_legs(legs), stroke_mm=drive_soft_limits(profile))


def _identity(r: ImportRequest, mapping) -> dict:
    """import_csv's identity keywords: the identity given (options, map, --config), checked now,
    the legs' part once the file is read (station/services/import_identity.py)."""
    from station.services import import_identity

    cfg = None
    if r.config:
        from station.services.config import load_config

        cfg = load_config(r.config)
    options = {"serial": r.serial, "part_number": r.part_number, "leg_type": r.leg_type,
               "screw_lot": r.screw_lot, "station": r.station, "stage": r.stage, "measured": r.measured}
    ii = import_identity.given(options, mapping.identity if mapping else None, str(mapping.path) if mapping else "",
                               cfg)
    if not ii.any and cfg is None:
        return {}
    return {"identity": lambda legs: ii.identity_json(legs, r.operator, __version__),
            "station_config": cfg.to_dict() if cfg is not None else None, "stage": ii.stage,
            "started_utc": ii.started_utc}


@dataclass
class PreparedImport(OfflineJob):
    request: ImportRequest
    limits: PointLimits
    mapping: ImportMap | None = None  # with --map
    identity: dict = field(default_factory=dict)

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.io.csv_io import import_csv

        r = self.request
        warnings: list[str] = []
        lines: list[str] = []
        keywords = dict(operator=r.operator, software_version=__version__, overwrite=r.force, limits=self.limits,
                        accept_implausible=r.accept_implausible, warnings=warnings, **self.identity)
        if self.mapping is None:
            session = import_csv(Path(r.csv), Path(r.out), **keywords)
        else:  # convert through the map; its problems are told in terms of the source file (lines, columns)
            from procedures.io.import_map import convert, source_message

            converted = convert(r.csv, self.mapping)
            with tempfile.TemporaryDirectory(prefix="station-import-") as tmp_dir:
                tmp = Path(tmp_dir) / f"{Path(r.csv).stem}.mapped.csv"
                tmp.write_text(converted.csv_text, encoding="utf-8")
                try:
                    session = import_csv(tmp, Path(r.out), **keywords)
                except InputError as exc:
                    raise InputError(source_message(str(exc), tmp, Path(r.csv), converted)) from None
            lines.append(f"map: {r.map} (" + ", ".join(f"{k} <- {v}" for k, v in converted.columns.items()) + ")")
        return JobOutcome("done", outputs=[Path(r.out)], lines=lines + warnings + import_lines(session, r),
                          data=session)


def prepare_import(request: ImportRequest, cfg: StationConfig | None = None) -> PreparedImport:
    """The output check, the ranges, the map and the identity given (each refusal one line naming
    the option or map key), before the file is read."""
    from procedures.io.outputs import check_output_file

    r = request
    check_output_file(r.out, force=r.force, suffixes=(".h5",))
    limits = import_limits(r.legs, r.profile)
    mapping = None
    if r.map:
        from procedures.io.import_map import load_map

        mapping = load_map(r.map)
    identity = _identity(r, mapping)  # checked before the file is read
    return PreparedImport(r, limits, mapping, identity, lines=[f"import {r.csv} -> {r.out}"])


def import_lines(session: Session, r: ImportRequest) -> list[str]:
    """What `station import` says about the session it wrote: points, legs, runs, the optional
    columns and the identity (or that none was given, and what that costs)."""
    pts = session.points
    legs = ", ".join(str(leg) for leg in session.legs)
    runs = len({(int(row["leg"]), int(row["run"])) for row in pts[["leg", "run"]]})
    optional = session.plan.get("optional_columns") or []
    lines = [f"imported {len(pts)} points (legs {legs}; {runs} runs) from {r.csv}",
             f"optional columns: {', '.join(optional) if optional else 'none (environment unknown)'}"]
    if session.identity.recorded:
        who = ", ".join(f"leg {leg} {session.identity.leg(leg).serial or '(no serial)'}"
                        + (f" type {session.identity.leg(leg).leg_type}" if session.identity.leg(leg).leg_type else "")
                        for leg in session.legs)
        lines.append(f"identity: {who}; station {session.identity.station.id or 'not stated'}; stage "
                     f"{session.plan.get('stage') or 'not stated (other)'}; measured {session.attrs.get('started_utc')}")
    else:
        lines.append("identity: none given (no serial, type or stage): the session cannot be decided or certified; "
                     "give --serial, --leg-type, --stage (or the map's [identity], or --config)")
    lines.append(f"session written: {r.out} (sha256 {session.sha256[:16]}...)")
    return lines
