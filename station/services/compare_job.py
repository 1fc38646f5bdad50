"""The station comparison job (issue 32 part 1, one shape for every job): `station compare` fills
a `CompareRequest`; `prepare_compare` makes every refusal before the costly evaluation (fewer than
two sessions, an output folder that exists, sessions of different stages or further apart than
[catalog] compare_window_days) and `PreparedCompare.run` evaluates each session's reference leg
(the one evaluation, station.services.report_jobs.session_decisions), compares the stations
(procedures.reporting.compare) and writes compare.json, compare.md and compare.png."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from procedures.vocabulary import InputError
from station.services.job import JobOutcome

if TYPE_CHECKING:
    from procedures.reporting.compare import StationRun


@dataclass
class CompareRequest:
    """Compare `sessions` (two or more session files) of the reference leg `serial` (None: the one
    serial every session holds) into the folder `out` (its files replaced only with `force`), on
    the raw error with `raw` (default: normalised to 20 degC); `config`: the station TOML whose
    [catalog] compare_window_days bounds how far apart the sessions may be (None: the built-in)."""

    sessions: list[Path]
    out: Path
    serial: str | None = None
    force: bool = False
    raw: bool = False
    config: Path | None = None


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


def run_of(session, serial: str | None, others: list, raw: bool) -> "StationRun":
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


@dataclass
class PreparedCompare:
    """A comparison that passed every check made before the evaluation; `run` evaluates, compares
    and writes. The outcome's `data` is the comparison (procedures.reporting.compare.compare's
    dict), `flagged` whether a station is flagged beyond chance."""

    request: CompareRequest
    sessions: list[Any]  # procedures.io.recording.reader.Session, in the order given
    out: Path
    needs_rig: bool = False
    question: str | None = None
    lines: list[str] = field(default_factory=list)

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.io.atomic_outputs import write_bytes_atomic  # never half a file
        from procedures.reporting import compare as cmp

        r, out = self.request, self.out
        runs = [run_of(s, r.serial, [o for o in self.sessions if o is not s], r.raw) for s in self.sessions]
        result = cmp.compare(runs)
        out.mkdir(exist_ok=True)
        files = [out / "compare.json", out / "compare.md", out / "compare.png"]
        write_bytes_atomic(files[0], (json.dumps(result, indent=2, allow_nan=False) + "\n").encode())
        write_bytes_atomic(files[1], cmp.markdown(result).encode())
        tmp = out / ".compare.png.tmp.png"
        cmp.plot(result, tmp)
        tmp.replace(files[2])
        lines = list(cmp.summary_lines(result)) + [f"wrote {f}" for f in files]
        return JobOutcome("done", outputs=files, lines=lines, data=result)


def flagged(outcome: JobOutcome) -> bool:
    """Whether the comparison flagged a station (`station compare` exits 1 then)."""
    return any(s["flagged"] for s in outcome.data["stations"])


def prepare_compare(request: CompareRequest, cfg: Any = None) -> PreparedCompare:
    """Every refusal before the evaluation (InputError, nothing written): fewer than two sessions,
    an existing output folder without `force` (checked before reading: never overwrites unasked),
    sessions of different stages or started further apart than the window. `cfg`: the station
    config (None: load `request.config`)."""
    from procedures.io.outputs import check_output_folder
    from procedures.io.recording.reader import read_session
    from procedures.reporting import compare as cmp

    r = request
    if len(r.sessions) < 2:
        raise InputError("give at least two sessions to compare")
    out = check_output_folder(r.out, force=r.force)  # before reading: never overwrites unasked
    if cfg is None:
        from station.services.config import load_config

        cfg = load_config(r.config)
    window_days = cfg.catalog.compare_window_days
    sessions = [read_session(Path(p)) for p in r.sessions]
    cmp.same_stage([(Path(s.path).name, s.stage) for s in sessions])  # before the costly evaluation
    cmp.within_window([(Path(s.path).name, s.attrs.get("started_utc")) for s in sessions], window_days)
    return PreparedCompare(r, sessions, Path(out))
