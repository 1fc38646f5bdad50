"""The verification job, for every front end (issue 32 part 1): `station verify` and the
Compensation page's verify (v) fill a `VerifyRequest`; `prepare_verify` makes every refusal,
output check and size estimate before anything connects or moves; the JobRunner
(station/services/job.py) runs the `PreparedVerify` on the rig (station.services.table_jobs.verify_job:
the tables checked, the sweep with them active, the comparison with the calibration, one audit
entry per leg); the outcome carries a `Verification` the front ends present.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Iterator

from procedures.vocabulary import InputError
from station.services.config import StationConfig
from station.services.job import JobOutcome, require_legs

if TYPE_CHECKING:  # annotations only: a request and its refusal load nothing of the procedures
    import numpy as np

    from procedures.acquisition.plans import SweepPlan
    from procedures.compensation.audit import AuditLog
    from procedures.compensation.verify import LegChecked, LegVerification
    from procedures.engine.control import RunControl
    from procedures.engine.runner import Sink
    from procedures.io.recording.reader import Session
    from station.services.wiring import Rig

VERIFY = "verify"  # the audit log's action of a verification (its entries' `action`)

NOISE_SEED_ENV = "STATION_SIM_NOISE_SEED"
"""Simulated rig only: the verification's noise seed when none is given (a demo or a test that
repeats exactly: tests/station/test_readme_calibration.py); unset = a new seed each time."""


def default_noise_seed() -> int:
    """$STATION_SIM_NOISE_SEED when set (InputError unless a whole number), else a new random seed."""
    text = os.environ.get(NOISE_SEED_ENV, "").strip()
    if not text:
        return secrets.randbelow(1 << 31)
    try:
        return int(text)
    except ValueError:
        raise InputError(f"${NOISE_SEED_ENV} = {text!r}: give a whole number (or unset it for a new seed)") from None


@dataclass
class VerifyRequest:
    """A verification as a front end asks for it: the `legs` (numbers, or their text "2", "1-3",
    "all"), the session file `out` (and `json_out` for the figures; `force`: replace them), the
    calibration `before` (a session file: its plan is repeated and its figures are the "before";
    None: an ISO 230-2 plan of `cycles`), the table CSV each leg's active table must be (`table`),
    `raw` (compare raw errors, not normalised to 20 degC), the audit log (`audit`, None: the
    station's), the simulated rig's `time_scale`, `seed` and `noise_seed`."""

    legs: tuple[int, ...] | str
    out: str | Path
    before: str | Path | None = None
    table: str | Path | None = None
    cycles: int | None = None
    json_out: str | Path | None = None
    force: bool = False
    raw: bool = False
    audit: str | Path | None = None
    time_scale: float | None = None
    seed: int | None = None
    noise_seed: int | None = None
    make_parents: bool = False


@dataclass
class Verification:
    """What a verification found, for a front end to present: the `report` (before vs after),
    each leg's `results` (procedures.compensation.verify.LegVerification: ratio, passed, ...),
    each leg's audit line (`audit_lines`), the as-left decisions (`as_left`: lines, and a
    one-line `as_left_summary`), the figures as JSON (`doc`)."""

    report: str
    results: dict[int, LegVerification]
    audit_lines: dict[int, str] = field(default_factory=dict)
    as_left: list[str] = field(default_factory=list)
    as_left_summary: str = ""
    doc: dict = field(default_factory=dict)
    session: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.results.values())


def leg_checked_line(event: object) -> str | None:
    """The line of a leg's active table as the verification found it (its LegChecked event), else None."""
    from procedures.compensation.verify import LegChecked

    if not isinstance(event, LegChecked):
        return None
    return f"leg {event.leg}: bank {event.bank} active, {event.description}, sha256 {event.table_sha256[:12]}…"


def verdict_parts(result: LegVerification) -> tuple[str, float | None, float, float | None]:
    """(verdict "pass" / "above" / "none", ratio, the limit, range reduction %) of a leg's result."""
    from procedures.compensation.verify import ACCEPT_RATIO

    ratio = result.ratio
    verdict = "none" if ratio is None else ("pass" if result.passed else "above")
    return verdict, ratio, ACCEPT_RATIO, result.range_reduction_pct


@dataclass
class PreparedVerify:
    """A verification that passed every check made without the devices (prepare_verify)."""

    request: VerifyRequest
    cfg: StationConfig
    out: Path
    legs: tuple[int, ...]
    plan: SweepPlan
    before: Session | None  # the calibration
    expected: dict[int, str]
    noise_seed: int | None
    audit: AuditLog
    lines: list[str] = field(default_factory=list)
    rig: Rig | None = None
    question: str | None = None
    needs_rig: bool = True
    kind: str = "verification"
    recorded: np.ndarray | None = None  # a resumed sweep's points (PreparedSweep's): none for a verification

    @property
    def total_points(self) -> int:
        return self.plan.total_points

    @contextlib.contextmanager
    def connect(self) -> Iterator[Rig]:
        """Open the rig for the verified legs (the simulated one with the verification's noise seed)."""
        from station.services.wiring import open_rig

        with open_rig(self.cfg, legs=self.legs, time_scale=self.request.time_scale, noise_seed=self.noise_seed) as rig:
            self.rig = rig
            try:
                yield rig
            finally:
                self.rig = None

    def rig_lines(self) -> list[str]:
        """What to say once the rig is open: which rig (with the simulated one's seeds) and each
        leg's compensation target."""
        from station.services.table_jobs import target_text

        seeds = f"; plant seed {self.cfg.sim.seed}, noise seed {self.noise_seed}" if self.cfg.is_sim else ""
        return [f"rig: {self.rig.description}{seeds}",
                *(f"compensation target of leg {leg}: {target_text(self.cfg, leg)}" for leg in self.legs)]

    def check(self) -> None:
        require_legs(None if self.rig is None else self.rig.axes, self.legs)

    def run(self, sinks: Iterable[Sink] = (), control: RunControl | None = None) -> JobOutcome:
        from procedures.compensation.audit import AuditRecord
        from procedures.compensation.verify import Verified
        from procedures.engine.events import SweepStarted
        from procedures.reporting.decision import decision_lines, decision_summary
        from procedures.reporting.evaluation import evaluate_points
        from station import __version__
        from station.services.session_identity import session_identity
        from station.services.table_jobs import as_recorded, verify_job
        from station.services.wiring import drive_url_of

        if self.request.force and self.out.exists():
            self.out.unlink()  # --force: the new verification session replaces it
        identity = session_identity(self.cfg, self.plan.legs, self.rig.axes, __version__)
        job = verify_job(self.rig, self.plan, self.out, self.cfg, audit=self.audit, before=self.before,
                         expected_sha256=self.expected, expected_source=str(self.request.table),
                         drive_url=drive_url_of(self.cfg), sinks=sinks, control=control, normalise=not self.request.raw,
                         identity=identity)
        if not job.of(Verified):
            return job  # refused (nothing moved) or broken off: its finished event says why
        verified = job.of(Verified)[-1]
        before = self.before
        doc = {"session": verified.session,
               "before": None if before is None else {"path": str(before.path), "sha256": before.sha256},
               "legs": {str(leg): r.to_json() for leg, r in verified.results.items()}}
        # as-left: the verification's ISO 230-2 values with U against [tolerances.TYPE] as_left
        # (docs/decisions.md), of the points it measured with the config and identity it recorded
        # (the same figures as the recording's, read back: tests/station/test_cli_verify_decisions.py)
        started = job.of(SweepStarted)[-1]
        as_left = evaluate_points(verified.points, plan=started.plan, devices=started.devices,
                                  station_config=as_recorded("station_config", self.cfg.to_dict()),
                                  identity=as_recorded("identity", identity.to_json()),
                                  source={"path": verified.session["path"], "sha256": verified.session["sha256"]},
                                  raw=self.request.raw, stage="as_left")["decisions"]
        doc["decisions"] = as_left
        audit_lines = {}
        for e in job.of(AuditRecord):
            audit_lines.setdefault(e.entry.leg, e.entry.message)
        try:  # the one line of the Compensation page ("" when no leg's type states a tolerance)
            summary = decision_summary(as_left["legs"])
        except Exception:  # noqa: BLE001 (a decision line is an extra; the verification's figures stand)
            summary = ""
        job.data = Verification(verified.report, dict(verified.results), audit_lines,
                                [f"As-left decisions ({as_left['rule']}):", *(f"  {x}" for x in decision_lines(as_left["legs"]))],
                                summary, doc, dict(verified.session))
        job.outputs = [self.out]
        if self.request.json_out:
            Path(self.request.json_out).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
            job.outputs.append(Path(self.request.json_out))
        return job


def _plan(request: VerifyRequest, legs: tuple[int, ...], before: Session | None) -> SweepPlan:
    from procedures.acquisition.plans import SweepPlan, iso230_plan

    if before is None:
        return iso230_plan(legs, cycles=5 if request.cycles is None else request.cycles)
    if request.cycles is not None:
        raise InputError("--cycles applies without --before only (the calibration's plan is repeated as it was)")
    try:
        plan = SweepPlan.from_dict(before.plan)
    except (InputError, TypeError, ValueError) as exc:
        raise InputError(f"{before.path}: its sweep plan cannot be repeated ({exc}); verify without --before") from None
    missing = [leg for leg in legs if leg not in before.legs]
    if missing:
        raise InputError(f"{before.path}: no calibration points for leg(s) {missing} (it has legs {before.legs})")
    return replace(plan, legs=legs, kind="verification", notes=())


def parse_leg_choice(text: str | tuple[int, ...]) -> tuple[int, ...]:
    """"3", "1-6", "1,4" or "all" as leg numbers; InputError naming what is wrong."""
    from procedures.acquisition.plans import parse_legs
    from station.services.config import LEG_COUNT

    if not isinstance(text, str):
        return tuple(int(x) for x in text)
    if text.strip().lower() == "all":
        return tuple(range(1, LEG_COUNT + 1))
    try:
        return parse_legs(text)
    except InputError:
        raise InputError(f"--leg {text}: give a leg number from 1 to {LEG_COUNT}, a range (1-6), a list (1,4) "
                         "or all") from None


def prepare_verify(request: VerifyRequest, cfg: StationConfig) -> PreparedVerify:
    """Every refusal of `request` before anything connects or moves: legs whose table the
    controller applies (refused and logged in the audit log, as every table refusal), the
    simulated rig's options on a real one, the output files, the calibration's plan repeated
    for these legs (or an ISO 230-2 plan sized against the config's [limits]), the expected
    table. InputError otherwise."""
    from procedures.io.outputs import check_output_file
    from procedures.io.recording.reader import read_session
    from station.services.session_identity import station_audit_log
    from station.services.sweep_job import check_time_scale
    from station.services.table_jobs import controller_refusal, expected_tables, refusal_job
    from station.services.wiring import drive_url_of, leg_table_spec

    legs = parse_leg_choice(request.legs)
    if not cfg.is_sim and (request.seed is not None or request.noise_seed is not None):
        raise InputError("--seed/--noise-seed apply to the simulated rig (--sim, or a config naming \"sim\") only")
    if request.seed is not None:
        cfg.sim.seed = request.seed
    audit = station_audit_log(cfg, request.audit)
    controller = controller_refusal(cfg, legs, VERIFY)
    if controller:  # the station cannot verify a table the controller applies: refused and logged
        job = refusal_job(VERIFY, controller[0], controller[1], audit=audit, drive_url=drive_url_of(cfg))
        raise InputError(job.finished.message)
    check_time_scale(request.time_scale)
    # every output checked before anything connects or moves (procedures/io/outputs.py)
    out = check_output_file(request.out, force=request.force, suffixes=(".h5",), make_parents=request.make_parents)
    if request.json_out:
        check_output_file(request.json_out, force=request.force, option="--json")
    before = read_session(request.before) if request.before else None
    lines = []
    if before is None:  # sized first against the config's [limits], as a sweep sizes its plan
        from procedures.acquisition.plan_size import check_plan_size
        from procedures.acquisition.plan_spec import PlanSpec

        size = check_plan_size(PlanSpec(legs=legs, kind="iso230", cycles=5 if request.cycles is None else request.cycles),
                               cfg.limits)
        lines.append(f"plan: {size.describe()}")
    plan = _plan(request, legs, before)
    expected: dict[int, str] = {}
    if request.table:
        for leg in legs:  # as the leg's table holder stores it: the drive, or the station (its target)
            expected.update(expected_tables(request.table, (leg,), leg_table_spec(cfg, leg)))
    noise_seed = None
    if cfg.is_sim:
        noise_seed = request.noise_seed if request.noise_seed is not None else default_noise_seed()
        if noise_seed == cfg.sim.seed:
            lines.append(f"note: noise seed {noise_seed} = plant seed: the sweep repeats the noise of a `station sweep "
                         "--sim` of the same plan exactly, so it is not an independent verification")
    return PreparedVerify(request, cfg, out, tuple(plan.legs), plan, before, expected, noise_seed, audit, lines)
