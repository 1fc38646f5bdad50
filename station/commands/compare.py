"""`station compare`: do stations agree? Sessions of one reference leg from several stations,
per target and direction E_n with both stations' U; a station flagged beyond chance."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.vocabulary import InputError
from procedures.io.atomic_outputs import write_bytes_atomic  # never half a file

if TYPE_CHECKING:
    from procedures.reporting import compare as cmp

NAME = "compare"
HELP = "station comparison: sessions of one reference leg from several stations, E_n per target, bias flagged"
DESCRIPTION = (
    "Compare sessions of the same reference leg (same serial; refused otherwise, naming both) and of the same "
    "stage (an as-found calibration with calibrations, an as-left verification with verifications) measured by "
    "different stations: per target and direction the mean deviation of each station against the mean of the "
    "others, E_n = d / sqrt(U^2 + U_ref^2) with each side's expanded U of that mean (the uncertainty budget), and "
    "a station flagged when |E_n| > 1 at more targets than chance allows (binomial at 5 %). Sessions started "
    "further apart than [catalog] compare_window_days of --config (default 90) are refused, as the web's /compare "
    "does not compare them: their difference is the leg's drift, not a station's bias. Writes compare.md, "
    "compare.json and compare.png into --out. docs/decisions.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sessions", type=V.SESSION.argtype(), nargs="+", metavar="FILE.h5", help="two or more sessions of the reference leg")
    p.add_argument("--serial", type=V.SERIAL.argtype(), help="the reference leg's serial (default: the one serial every session holds)")
    p.add_argument("--out", type=V.OUT_DIR.argtype(), required=True, metavar="DIR", help="folder for compare.md/.json/.png (created; its parent must exist)")
    p.add_argument("--force", action="store_true", help="replace compare.md/.json/.png in an existing --out (default: refused)")
    p.add_argument("--raw", action="store_true", help="compare the raw error (default: normalised to 20 degC)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C",
                   help="station TOML whose [catalog] compare_window_days bounds how far apart the sessions may be "
                        "(the web's /compare uses the same; default 90 days)")


def _leg_of(session, serial: str | None, others: list) -> tuple[int, str]:
    serials = {session.identity.leg(leg).serial: leg for leg in session.legs if session.identity.leg(leg).serial}
    if not serials:
        raise InputError(f"{session.path}: records no leg serial; a comparison needs the reference leg's serial "
                         "(sweep it with --serial LEG=SERIAL)")
    if serial is not None:
        if serial not in serials:
            raise InputError(f"{session.path}: holds leg(s) {', '.join(sorted(serials))}, not {serial}")
        return serials[serial], serial
    common = set(serials)
    for o in others:
        mine = {o.identity.leg(leg).serial for leg in o.legs} - {None}
        if not common & mine:
            raise InputError(f"{session.path} measured leg {', '.join(sorted(serials))} but {o.path} measured leg "
                             f"{', '.join(sorted(mine)) or '(no serial)'}: compare sessions of the same reference leg")
        common &= mine
    if len(common) > 1:
        raise InputError(f"the sessions share legs {', '.join(sorted(common))}: say which with --serial")
    s = common.pop()
    return serials[s], s


def run_of(session, serial: str | None, others: list, raw: bool) -> cmp.StationRun:
    """One session as a StationRun of its reference leg (the ISO 230-2 report's targets with U)."""
    from procedures.reporting import compare as cmp
    from station.services.report_jobs import session_decisions

    leg, serial = _leg_of(session, serial, others)
    iso = session_decisions(session, raw)
    L = iso["legs"].get(str(leg))
    if L is None or not L["targets"]:
        raise InputError(f"{session.path}: no measured points of leg {leg} ({serial})")
    station = session.identity.station.id or "unknown station"
    return cmp.StationRun(f"{station} ({Path(session.path).name})", station, Path(session.path).name, leg, serial,
                          tuple((t["direction"], t["target_mm"], t["mean_um"], t["U_um"]) for t in L["targets"]),
                          L["values"], stage=session.stage)


def run(args) -> int:
    from procedures.io.outputs import check_output_folder
    from procedures.io.recording.reader import read_session
    from procedures.reporting import compare as cmp

    if len(args.sessions) < 2:
        raise InputError("give at least two sessions to compare")
    out = check_output_folder(args.out, force=args.force)  # before reading: never overwrites unasked
    from station.services.config import load_config

    window_days = load_config(args.config).catalog.compare_window_days
    sessions = [read_session(Path(p)) for p in args.sessions]
    cmp.same_stage([(Path(s.path).name, s.stage) for s in sessions])  # before the costly evaluation
    cmp.within_window([(Path(s.path).name, s.attrs.get("started_utc")) for s in sessions], window_days)
    runs = [run_of(s, args.serial, [o for o in sessions if o is not s], args.raw) for s in sessions]
    result = cmp.compare(runs)
    out.mkdir(exist_ok=True)
    files = [out / "compare.json", out / "compare.md", out / "compare.png"]
    write_bytes_atomic(files[0], (json.dumps(result, indent=2, allow_nan=False) + "\n").encode())
    write_bytes_atomic(files[1], cmp.markdown(result).encode())
    tmp = out / ".compare.png.tmp.png"
    cmp.plot(result, tmp)
    tmp.replace(files[2])
    for line in cmp.summary_lines(result):
        print(line)
    for f in files:
        print(f"wrote {f}")
    return 1 if any(s["flagged"] for s in result["stations"]) else 0
