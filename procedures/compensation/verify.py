"""Verification of a compensation: the compensated error of a sweep, before and after.

`verify(after_points, before_points)` compares a verification sweep (table active) with the
calibration session it was made from, per leg: the error RMS and range, the noise floor and the
ISO 230-2 values (procedures.reporting.iso230), side by side.

Definitions (docs/compensation.md), errors measured minus commanded, um:

- residual RMS: the root mean square of a session's errors about their mean. The mean is left
  out because an interferometer measures displacement from the point where it was zeroed:
  a constant is the reference of the session, not an error of the leg (with a table active the
  zero point itself is corrected, which shifts every reading by the table's value there, and
  the drive's backlash state at the zero point may differ). The mean is reported beside it.
- noise floor: the pooled pass-to-pass standard deviation over (target, direction) cells with
  at least two passes (procedures.fit.noise, the same figure `station fit` reports): what a
  perfect static table would leave, i.e. measurement noise, pass offsets, and the thermal and
  drift changes from pass to pass within the session.
- ratio = residual RMS / noise floor of the verification session. A table that compensates
  every systematic error exactly scores sqrt((n - 1) / n) for n cycles when the conditions
  repeat (about 0.89 for 5 cycles) and about 1 otherwise; systematic residuals add in
  quadrature. The acceptance limit is 1.1. The ratio scatters with the verification's own pass
  offsets, which its floor and residual both rest on: where they dominate (the simulated legs),
  a perfect table reads above 1.1 on about 1 leg in 25 with 5 cycles and practically never with
  20 (bench/bench_throughput.py's oracle row; `next_step` says so for a verdict just above).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Iterator, Mapping

import numpy as np

from drivers.errors import DriverError
from drivers.interfaces import Clock, Interferometer, ServoAxis
from procedures.engine import events as ev
from procedures.compensation.audit import Action, AuditEntry, AuditRecord
from procedures.engine.control import RunControl
from procedures.vocabulary import InputError, Outcome
from procedures.fit.data import split_legs
from procedures.fit.dynamic import is_onthefly, static_points
from procedures.fit.noise import estimate_noise_floor
from procedures.reporting.iso230 import LegIso230, evaluate_leg
from procedures.metrology.thermal import normalise_session
from procedures.acquisition.plans import SweepPlan
from procedures.compensation.push import compensation_target, describe_table, drive_table_spec, OperationFinished, PushRefused, refused, table_sha256
from procedures.acquisition.sweep import sweep
from procedures.io.recording.schema import POINT_DTYPE

if TYPE_CHECKING:  # the annotation only: the caller's reader reads the calibration session
    from procedures.io.recording.reader import Session

ACCEPT_RATIO = 1.1
"""A verified leg passes when its residual RMS is at most this times its noise floor."""

ISO_SHOWN = ("E", "M", "A", "R", "B")
THERMAL_NOTE_K = 0.1  # a material temperature difference worth pointing out (about 0.2 um over 180 mm)
SCREW_RESOLVING_SPACING_MM = 1.25
"""Calibration targets further apart than this cannot resolve a ball screw's once-per-turn error
(leads of 4..10 mm, a quarter of the shortest), so neither can a table made from them: the
ISO 230-2 plan's 11 targets over 180 mm are 16 mm apart. README, calibration: `--step 1`."""


@dataclass(frozen=True)
class ErrorSummary:
    """The error of one leg in one session, um (measured minus commanded).

    `rms_um` about the mean, `rms_raw_um` including it, `range_um` max - min; `noise_floor_um`
    and `within_pass_um` as procedures.fit.noise (None without repeat passes).
    """

    n_points: int
    n_cycles: int
    mean_um: float
    rms_um: float
    rms_raw_um: float
    range_um: float
    noise_floor_um: float | None
    within_pass_um: float | None
    iso: LegIso230
    material_temp_c: float | None = None  # mean over the leg's points; None when not recorded
    target_spacing_mm: float | None = None  # median spacing of the leg's distinct targets; None for one target

    def to_json(self) -> dict[str, Any]:
        return {
            "n_points": self.n_points, "n_cycles": self.n_cycles, "mean_um": self.mean_um, "rms_um": self.rms_um,
            "rms_raw_um": self.rms_raw_um, "range_um": self.range_um, "noise_floor_um": self.noise_floor_um,
            "within_pass_um": self.within_pass_um, "material_temp_c": self.material_temp_c,
            "target_spacing_mm": self.target_spacing_mm,
            "iso230": {k: self.iso.values.get(k) for k in self.iso.values},
            "iso230_not_computed": dict(self.iso.reasons),
        }


@dataclass(frozen=True)
class LegVerification:
    """One leg: `after` (the verification sweep) and `before` (the calibration, if given)."""

    leg: int
    after: ErrorSummary
    before: ErrorSummary | None = None

    @property
    def ratio(self) -> float | None:
        """Residual RMS of the verification / its noise floor (None without a floor)."""
        f = self.after.noise_floor_um
        return self.after.rms_um / f if f else None

    @property
    def passed(self) -> bool | None:
        r = self.ratio
        return None if r is None else r <= ACCEPT_RATIO

    @property
    def rms_reduction_pct(self) -> float | None:
        if self.before is None or self.before.rms_um <= 0:
            return None
        return 100.0 * (1.0 - self.after.rms_um / self.before.rms_um)

    @property
    def range_reduction_pct(self) -> float | None:
        if self.before is None or self.before.range_um <= 0:
            return None
        return 100.0 * (1.0 - self.after.range_um / self.before.range_um)

    def to_json(self) -> dict[str, Any]:
        return {
            "leg": self.leg, "ratio": self.ratio, "passed": self.passed, "accept_ratio": ACCEPT_RATIO,
            "rms_reduction_pct": self.rms_reduction_pct, "range_reduction_pct": self.range_reduction_pct,
            "after": self.after.to_json(), "before": None if self.before is None else self.before.to_json(),
        }


def summarize(points: np.ndarray, leg: int, source: str = "the session") -> ErrorSummary:
    """ErrorSummary of `leg` in a session's points (POINT_DTYPE). InputError when the leg has
    no usable points."""
    data = split_legs(points, source=source).get(int(leg))
    if data is None or data.n_points == 0:
        raise InputError(f"{source}: no measured points for leg {leg}")
    e = data.error_um
    mean = float(np.mean(e))
    nf = estimate_noise_floor(data)
    pts = np.asarray(points)
    temps = pts["material_temp_c"][pts["leg"] == int(leg)]
    temps = temps[np.isfinite(temps)]
    targets = np.unique(np.round(pts["target_mm"][pts["leg"] == int(leg)], 6))
    return ErrorSummary(
        n_points=data.n_points,
        n_cycles=data.n_cycles,
        mean_um=mean,
        rms_um=float(np.sqrt(np.mean((e - mean) ** 2))),
        rms_raw_um=float(np.sqrt(np.mean(e**2))),
        range_um=float(np.ptp(e)),
        noise_floor_um=nf.noise_floor_um,
        within_pass_um=nf.within_pass_um,
        iso=evaluate_leg(np.asarray(points), int(leg)),
        material_temp_c=float(np.mean(temps)) if temps.size else None,
        target_spacing_mm=float(np.median(np.diff(targets))) if targets.size > 1 else None,
    )


def verify(after_points: np.ndarray, before_points: np.ndarray | None = None, legs: Iterable[int] | None = None,
           after_source: str = "the verification session", before_source: str = "the calibration session",
           ) -> dict[int, LegVerification]:
    """Per-leg verification figures (see the module docstring) for `legs` (default: every leg
    of the verification). InputError when a leg has no points in either session."""
    # on-the-fly readings: their static part, as `station fit` takes it (procedures/fit/dynamic.py),
    # so the noise floor and residual are those of the error the table corrects, not of two speeds
    if len(after_points) and is_onthefly(after_points):
        after_points = static_points(after_points, after_source)
    if before_points is not None and len(before_points) and is_onthefly(before_points):
        before_points = static_points(before_points, before_source)
    after_legs = sorted({int(v) for v in np.asarray(after_points)["leg"]}) if len(after_points) else []
    chosen = sorted({int(x) for x in legs}) if legs is not None else after_legs
    if not chosen:
        raise InputError(f"{after_source}: no measured points")
    out: dict[int, LegVerification] = {}
    for leg in chosen:
        after = summarize(after_points, leg, after_source)
        before = summarize(before_points, leg, before_source) if before_points is not None else None
        out[leg] = LegVerification(leg, after, before)
    return out


def _f(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return f"{'-':>8}"
    return f"{value:8.3f}"


def format_report(results: dict[int, LegVerification]) -> str:
    """Before / after side by side per leg (um), with the ratio and verdict."""
    lines: list[str] = []
    for leg, r in results.items():
        b, a = r.before, r.after
        lines.append(f"Leg {leg}: compensated error, um (measured minus commanded)"
                     + ("" if b else "  [no calibration session given: after only]"))
        lines.append(f"  {'':28} {'before':>8} {'after':>8}")

        def row(label: str, get) -> None:
            lines.append(f"  {label:28} {_f(get(b)) if b else _f(None)} {_f(get(a))}")

        row("residual RMS (about mean)", lambda s: s.rms_um)
        row("range (max - min)", lambda s: s.range_um)
        row("mean (zero reference)", lambda s: s.mean_um)
        row("noise floor (repeat passes)", lambda s: s.noise_floor_um)
        for name in ISO_SHOWN:
            row(f"ISO 230-2 {name}", lambda s, n=name: s.iso.values.get(n))
        ratio = r.ratio
        verdict = ("n/a (no repeat passes)" if ratio is None else
                   f"{ratio:.3f} -> {'PASS' if r.passed else 'ABOVE'} (limit {ACCEPT_RATIO:g})")
        lines.append(f"  verification ratio (residual RMS / noise floor): {verdict}")
        red = r.range_reduction_pct
        if red is not None:
            lines.append(f"  range reduction: {red:.1f} %, RMS reduction: {r.rms_reduction_pct:.1f} %")
        if b and b.material_temp_c is not None and a.material_temp_c is not None:
            dt_k = a.material_temp_c - b.material_temp_c
            if abs(dt_k) >= THERMAL_NOTE_K:
                lines.append(
                    f"  note: the leg was {abs(dt_k):.2f} K {'warmer' if dt_k > 0 else 'colder'} during verification "
                    f"({a.material_temp_c:.2f} C) than during calibration ({b.material_temp_c:.2f} C); thermal "
                    "expansion (steel ~11.5 um/m/K) is not in a static table: let the leg settle to the "
                    "calibration temperature, or see `station diagnose`")
        for note in a.iso.notes:
            lines.append(f"  note (after): {note}")
        if r.passed is False:
            lines.append(f"  next: {next_step(r)}")
        lines.append("")
    return "\n".join(lines)


FEW_VERIFY_CYCLES = 10
"""Below this many cycles a verification's ratio scatters by about +/- 0.1 for a perfect table."""
NEAR_LIMIT_RATIO = 1.3
"""Up to this ratio an ABOVE verdict from few cycles may be the verification's own scatter."""


def next_step(r: LegVerification) -> str:
    """What a technician does after an ABOVE verdict for leg `r.leg`: the likeliest cause first."""
    b, a = r.before, r.after
    again = "fit, make the table (its step follows the recording), push it and verify again"
    if b is not None and b.target_spacing_mm is not None and b.target_spacing_mm > SCREW_RESOLVING_SPACING_MM:
        return (f"the calibration's targets are {b.target_spacing_mm:.3g} mm apart, too far apart to resolve the "
                f"screw's once-per-turn error, so the table cannot correct it: calibrate again with targets every 1 mm "
                f"(`station sweep --step 1 --cycles 8 --legs {r.leg} ...`), {again} (README, calibration)")
    if b is not None and b.material_temp_c is not None and a.material_temp_c is not None \
            and abs(a.material_temp_c - b.material_temp_c) >= THERMAL_NOTE_K:
        return "let the leg settle to the calibration's temperature and verify again (see the note above)"
    diagnose = (f"`station diagnose` on the calibration names what the table leaves; calibrate again (more "
                f"--cycles, or targets every 1 mm: `station sweep --step 1 --cycles 8 --legs {r.leg} ...`), {again}")
    if a.n_cycles < FEW_VERIFY_CYCLES and r.ratio is not None and r.ratio <= NEAR_LIMIT_RATIO:
        return (f"a {a.n_cycles}-cycle verification's ratio rests on {2 * a.n_cycles} pass offsets and scatters: a perfect "
                f"table reads above {ACCEPT_RATIO:g} on about 1 leg in 25 with 5 cycles (docs/onthefly.md, Figures); "
                f"verify again with more cycles (`station verify --leg {r.leg} --cycles 20 ...`) before calibrating "
                f"again; if it stays above: {diagnose}")
    return diagnose


# -- the procedure ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class LegChecked(ev.Event):
    """A verification found `leg`'s table active and fit to verify: `bank`, `table_sha256`,
    `description` (points, span, largest correction)."""

    leg: int
    drive: str
    bank: int
    table_sha256: str
    description: str


@dataclass(frozen=True)
class Verified(ev.Event):
    """A verification's figures (a LegVerification per leg), after its sweep, and the `points`
    they were computed from: the sweep's points as measured (POINT_DTYPE rows in the order the
    recorder wrote them, raw error), for a caller's further figures of the same data (the
    as-left decisions) without reading the recording back."""

    results: dict[int, LegVerification]
    report: str
    session: dict[str, Any]
    points: np.ndarray


@dataclass(frozen=True)
class MeasuredPoints:
    """A sweep's points as measured (POINT_DTYPE) with the station config recorded beside them
    (the materials of the normalisation to 20 degC): what `error_basis` reads of a session."""

    points: np.ndarray
    station_config: Mapping[str, Any] | None


@dataclass(frozen=True)
class ActiveTable:
    """What one leg's drive applies before a verification (read from the drive)."""

    leg: int
    drive: str
    bank: int
    table_sha256: str
    description: str
    target: str = "drive"  # who applies the table: "drive" or "station" (procedures.compensation.push.compensation_target)


def verify_procedure(
    axes: dict[int, ServoAxis], laser: Interferometer, clock: Clock, plan: SweepPlan, out: str | Path, *,
    recording_sha256: Callable[[Path], str], station_config: Mapping[str, Any] | None = None,
    before: Session | None = None, expected_sha256: dict[int, str] | None = None,
    expected_source: str = "the table", drive_url: str = "", control: RunControl | None = None,
    sweep_options: dict[str, Any] | None = None, normalise: bool = True,
) -> Iterator[ev.Event]:
    """A verification as events for the one runner: check each leg's active table, sweep
    `plan` with it active (the sweep's events; a recorder sink writes them to `out`), then
    compare with the calibration `before` (a session as procedures.io.recording.reader reads it, or
    None) and log one audit entry per leg.

    Refused (an `AuditRecord` and `OperationFinished(refused)`, nothing moves) when a leg's
    active table is empty, its drive does not apply it (table_enable = 0), or it is not the
    one in `expected_sha256` (per leg, hashed as the drive holds it). After the sweep: `Verified`
    (figures and the report), one `AuditRecord` per leg with the sweep's outcome, and
    `OperationFinished` (completed / aborted / failed).

    The figures are computed from the points the sweep yields (the ones the recorder writes),
    with `station_config` the recorder records (its materials normalise them), not read back
    from `out`; `recording_sha256(out)` names the finished recording (the recorder sink
    finishes it on `SweepFinished`) in the figures and the audit entries.

    `normalise` (default): both sessions' errors are normalised to 20 degC material temperature
    with the materials each recorded (procedures.metrology.thermal), and the report says so;
    False compares the raw errors.
    """


    expected = expected_sha256 or {}
    active: dict[int, ActiveTable] = {}
    for leg in plan.legs:
        axis = axes[leg]
        target = compensation_target(axis)
        holder = "the station" if target == "station" else "the drive"
        try:
            drive_table_spec(axis, "verify")  # a drive without a table: refused, naming the other targets
        except PushRefused as exc:
            yield from refused(Action.VERIFY, leg, exc.args[0], drive_url=drive_url, details={"target": target})
            return
        try:
            st = axis.status()
            identity = axis.identity()
            bank = axis.active_bank()
            table = axis.read_table(bank)
        except DriverError as exc:
            yield from refused(Action.VERIFY, leg, f"leg {leg}: cannot read the drive's table before the verification "
                               f"({exc.args[0] if exc.args else exc})", drive_url=drive_url, details={"target": target})
            return
        sha = table_sha256(table)
        problem = ""
        if table.point_count == 0:
            problem = (f"leg {leg}: {holder}'s active table (bank {bank}) is empty; push a table first (`station push`"
                       + ("; compensation target station)" if target == "station" else ")"))
        elif not st.table_enabled:
            problem = f"leg {leg}: {holder} does not apply its table (table compensation off); switch it on first"
        elif leg in expected and expected[leg] != sha:
            problem = (f"leg {leg}: {holder}'s active table (sha256 {sha[:12]}…) is not the leg's rows of {expected_source} "
                       f"(sha256 {expected[leg][:12]}…); push it first")
        if problem:
            yield AuditRecord(AuditEntry(Action.VERIFY, leg, Outcome.REFUSED, problem, identity, drive_url,
                                            table_sha256=sha, bank=bank, details={"target": target}))
            yield OperationFinished(Action.VERIFY, leg, Outcome.REFUSED, problem)
            return
        active[leg] = ActiveTable(leg, identity, bank, sha, f"{describe_table(table)}; target {target}", target)
        yield LegChecked(leg, identity, bank, sha, active[leg].description)

    def log_all(outcome: str, message: str, details: dict[str, Any] | None = None) -> Iterator[ev.Event]:
        for leg, a in active.items():
            yield AuditRecord(AuditEntry(Action.VERIFY, leg, outcome, message, a.drive, drive_url,
                                            table_sha256=a.table_sha256, bank=a.bank,
                                            details={"target": a.target, **(details or {})}))

    out = Path(out)
    finished: ev.SweepFinished | None = None
    rows: list[tuple] = []  # the measured points, as the recorder writes them
    try:
        for event in sweep(plan, axes, laser, clock, control=control, **(sweep_options or {})):
            if isinstance(event, ev.PointMeasured):
                rows.append(event.record.to_row())
            elif isinstance(event, ev.SweepFinished):
                finished = event
            yield event
    except Exception as exc:  # a device gone mid-sweep: the audit log says so, then the error goes on up
        yield from log_all(Outcome.FAILED, f"verification sweep failed: {exc}", {"session": str(out)})
        raise
    outcome = Outcome(finished.outcome) if finished is not None else Outcome.FAILED
    measured = MeasuredPoints(np.array(rows, POINT_DTYPE), station_config)
    unmeasured = sorted(set(active) - {int(v) for v in measured.points["leg"]})
    if outcome != Outcome.COMPLETED and unmeasured:
        # stopped before a leg's first point (a link lost while preparing): no figures to compare
        text = (f"the verification sweep did not complete ({outcome}: {finished.reason if finished is not None else ''}); "
                f"no point measured on leg(s) {unmeasured}, so no figures")
        yield from log_all(outcome, text, {"session": str(out)})
        yield OperationFinished(Action.VERIFY, None, outcome, text, {})
        return
    after_points, before_points, basis, basis_doc = error_basis(measured, before, normalise)
    results = verify(after_points, before_points, list(active),
                     after_source=str(out), before_source=str(before.path) if before is not None else "")
    sha256 = recording_sha256(out)
    doc = {"path": str(out), "sha256": sha256, "outcome": str(outcome),
           "reason": finished.reason if finished is not None else "", "error_basis": basis_doc}
    yield Verified(results, "\n".join(basis) + "\n" + format_report(results), doc, measured.points)
    for leg, r in results.items():
        a = active[leg]
        details = {"target": a.target, "session": str(out), "session_sha256": sha256, **r.to_json()}
        if before is not None:
            details["before_session"] = {"path": str(before.path), "sha256": before.sha256}
        yield AuditRecord(AuditEntry(Action.VERIFY, leg, outcome, summary_line(outcome, r),
                                        a.drive, drive_url, table_sha256=a.table_sha256, bank=a.bank, details=details))
    failed = [leg for leg, r in results.items() if not r.passed]
    if outcome != Outcome.COMPLETED:
        text = f"the verification sweep did not complete ({outcome}: {doc['reason']})"
    elif failed:
        text = f"leg(s) {failed}: residual RMS above {ACCEPT_RATIO:g} x the noise floor (or no floor)"
    else:
        text = f"leg(s) {sorted(results)}: residual RMS within {ACCEPT_RATIO:g} x the noise floor"
    yield OperationFinished(Action.VERIFY, None, outcome, text, results)


def error_basis(session: Session | MeasuredPoints, before: Session | None,
                normalise: bool) -> tuple[np.ndarray, np.ndarray | None, list[str], dict]:
    """The verification's (`session`: as measured, or a session file as read) and the
    calibration's points as compared: normalised to 20 degC with the materials each session
    recorded (`normalise`), or raw; with the lines saying which."""
    before_points = before.points if before is not None else None
    if not normalise:
        return session.points, before_points, ["error: raw, not normalised to 20 degC (--raw)"], {"normalised": False}
    after = normalise_session(session.points, getattr(session, "station_config", None))
    lines = [f"verification {after.lines()[0]}", *after.lines()[1:]]
    doc = {"normalised": True, "verification": after.to_json()}
    if before is not None:
        cal = normalise_session(before.points, getattr(before, "station_config", None))
        before_points = cal.points
        lines += [f"calibration {cal.lines()[0]}", *cal.lines()[1:]]
        doc["calibration"] = cal.to_json()
    return after.points, before_points, lines, doc


def summary_line(outcome: str, r: LegVerification) -> str:
    """One line of a leg's verification, as the audit log and the front ends show it."""
    ratio = r.ratio
    return (f"verification {outcome}: residual RMS {r.after.rms_um:.4f} um, noise floor "
            + (f"{r.after.noise_floor_um:.4f} um, verification ratio {ratio:.3f} ({'pass' if r.passed else 'above'} {ACCEPT_RATIO:g})"
               if ratio is not None else "n/a"))
