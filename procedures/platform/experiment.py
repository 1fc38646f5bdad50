"""The seed paper's platform experiment (Section 4, Table 2): leg errors -> pose errors, and what
compensation leaves of them.

Steps, for N random reachable poses (seeded):
1. IK gives each leg's nominal length; its position is length minus mid-stroke (mm).
2. The direction each leg approaches its position from: the poses are visited in the order drawn
   (a random tour starting from the home pose), so a leg's direction is the sign of its motion
   from the previous pose (+1 = getting longer); an unchanged leg keeps its last direction.
3. Each leg gets an error (um, measured minus commanded) from the error source at that position
   and direction, and the compensation's prediction of it.
4. FK from the erroneous lengths (nominal + error) gives the erroneous pose; FK from the
   compensated lengths (nominal + error - prediction) the compensated one. Pose errors are those
   poses minus the nominal pose: x, y, z in um, angles in rad (also reported in arc-seconds).
   The measured error is taken at the nominal position (the compensation moves a leg by a few
   um, far less than the spacing of anything in the error curves).

Error sources (LegErrorSampler): `RecordedLegErrors` takes a session's points. The "measurement"
for a pose is either the mean of all passes of that leg in that direction (the systematic error,
the paper's setting: its model against the data it was fitted to), or one pass chosen at random
(repeatability included: what one leg in service may show), interpolated linearly. The
compensation is a fitted model's `predict_um`, a compensation table as the drive interpolates it,
or the mean of the *other* passes in that direction (leave one out, so the table never contains
the pass it corrects). `reduction_digest` condenses a run so that two measurements can be
reported side by side on the same poses; `run_measurements` runs both and sets them side by side.
`FunctionLegErrors` takes plain callables `leg_error_um(leg, position_mm, direction)`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from procedures.vocabulary import InputError
from procedures.platform.geometry import Geometry
from procedures.platform.kinematics import FkStatus, forward_kinematics, in_stroke, inverse_kinematics, leg_positions_mm
from procedures.platform.sensitivity import ARCSEC_PER_RAD, POSE_ERROR_FIELDS, pose_error_contributions

LegErrorFn = Callable[[int, np.ndarray, np.ndarray], np.ndarray]
"""leg (1-6), position_mm (array), direction (array of +1/-1) -> error_um (array, measured minus commanded)."""


class LegErrorSampler(Protocol):
    """Where the experiment gets leg errors and their predicted (compensation) values."""

    description: str

    def position_range_mm(self, leg: int) -> tuple[float, float]:
        """Positions (mm from mid-stroke) where this source has errors for `leg`."""
        ...

    def sample_um(self, leg: int, position_mm: np.ndarray, direction: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(measured_um, predicted_um) for `leg` at each position and direction."""
        ...


@dataclass
class FunctionLegErrors:
    """Errors from callables. `predicted_um` None means no compensation (prediction 0)."""

    measured_um: LegErrorFn
    predicted_um: LegErrorFn | None = None
    range_mm: tuple[float, float] = (-np.inf, np.inf)
    description: str = "leg error functions"

    def position_range_mm(self, leg: int) -> tuple[float, float]:
        return self.range_mm

    def sample_um(self, leg, position_mm, direction, rng):
        x = np.asarray(position_mm, dtype=float)
        d = np.asarray(direction)
        meas = np.broadcast_to(np.asarray(self.measured_um(leg, x, d), dtype=float), x.shape)
        pred = np.zeros_like(x) if self.predicted_um is None else np.broadcast_to(np.asarray(self.predicted_um(leg, x, d), dtype=float), x.shape)
        return np.array(meas), np.array(pred)


@dataclass
class _PassTable:
    grid_mm: np.ndarray  # (G,) sorted target positions
    passes_um: np.ndarray  # (P, G) each pass interpolated onto the grid
    runs: np.ndarray  # (P,) run numbers


def _interp_rows(grid: np.ndarray, values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Linear interpolation of values[j] (one row per x) on `grid`; end values held outside."""
    xc = np.clip(x, grid[0], grid[-1])
    k = np.clip(np.searchsorted(grid, xc, side="right") - 1, 0, grid.size - 2)
    t = (xc - grid[k]) / (grid[k + 1] - grid[k])
    rows = np.arange(x.size)
    return values[rows, k] * (1.0 - t) + values[rows, k + 1] * t


class RecordedLegErrors:
    """Leg errors from a recording's points (POINT_DTYPE), per leg and direction of approach.

    The measurement at a pose is one randomly chosen pass of the leg in that direction,
    interpolated linearly between its targets (`measurement="pass"`), or the mean of all passes
    in that direction (`"mean"`: the systematic error only, the paper's setting; needs a model or
    a table). The prediction is `predicted_um(leg, x, dir)` when given (a fitted model, or a
    compensation table as the drive interpolates it; `compensation` names it in the description),
    else the mean over the other passes in that direction at that
    position (leave-one-out table). Passes that do not span the leg's recorded range are left out
    (`dropped_runs`); at least two full passes per leg and direction are needed.
    """

    def __init__(self, points: np.ndarray, predicted_um: LegErrorFn | None = None, source: str = "the recording",
                 measurement: str = "pass", compensation: str = "the model's prediction"):
        if measurement not in ("pass", "mean"):
            raise InputError(f"measurement must be 'pass' or 'mean', got {measurement!r}.")
        if measurement == "mean" and predicted_um is None:
            raise InputError(
                "measuring with the mean of all passes needs a model as compensation (MODEL.json): "
                "the mean of the other passes would be the measurement itself."
            )
        self.source = source
        self.predicted_um = predicted_um
        self.measurement = measurement
        self.description = (
            f"{source}: "
            + ("one pass per pose and leg as measurement, " if measurement == "pass" else "mean of all passes per direction as measurement, ")
            + (f"{compensation} as compensation" if predicted_um else "mean of the other passes (leave-one-out) as compensation")
        )
        self.dropped_runs: dict[int, list[int]] = {}
        self._tables: dict[tuple[int, int], _PassTable] = {}
        self._range: dict[int, tuple[float, float]] = {}
        pts = np.asarray(points)
        for name in ("leg", "run", "direction", "target_mm", "error_um"):
            if pts.dtype.names is None or name not in pts.dtype.names:
                raise InputError(f"{source}: the points have no field {name!r}; expected the session point schema.")
        good = np.isfinite(pts["target_mm"]) & np.isfinite(pts["error_um"])
        pts = pts[good]
        if pts.size == 0:
            raise InputError(f"{source}: no points with a finite target_mm and error_um.")
        for leg in np.unique(pts["leg"]):
            leg = int(leg)
            lp = pts[pts["leg"] == leg]
            lo, hi = float(lp["target_mm"].min()), float(lp["target_mm"].max())
            for direction in (1, -1):
                dp = lp[lp["direction"] == direction]
                table = self._build(leg, direction, dp, lo, hi)
                self._tables[(leg, direction)] = table
            self._range[leg] = (lo, hi)

    def _build(self, leg: int, direction: int, dp: np.ndarray, lo: float, hi: float) -> _PassTable:
        name = "+1" if direction > 0 else "-1"
        grid = np.unique(dp["target_mm"])
        rows, runs = [], []
        for run in np.unique(dp["run"]):
            rp = dp[dp["run"] == run]
            order = np.argsort(rp["target_mm"], kind="stable")
            x, e = rp["target_mm"][order], rp["error_um"][order]
            if x.size < 2 or x[0] > lo + 1e-9 or x[-1] < hi - 1e-9:
                self.dropped_runs.setdefault(leg, []).append(int(run))
                continue
            # repeated targets within one pass (retries) are averaged
            ux, inv = np.unique(x, return_inverse=True)
            ue = np.bincount(inv, weights=e) / np.bincount(inv)
            rows.append(np.interp(grid, ux, ue))
            runs.append(int(run))
        need = 1 if self.predicted_um is not None else 2
        if len(rows) < need or grid.size < 2:
            raise InputError(
                f"{self.source}: leg {leg} has {len(rows)} complete pass(es) in direction {name} "
                f"over {lo:+.3f}..{hi:+.3f} mm; the platform experiment needs at least {need} "
                "(one as measurement, the others as the compensation table). Record more cycles."
            )
        return _PassTable(grid, np.array(rows), np.array(runs))

    @property
    def legs(self) -> tuple[int, ...]:
        return tuple(sorted(self._range))

    def position_range_mm(self, leg: int) -> tuple[float, float]:
        try:
            return self._range[leg]
        except KeyError:
            raise InputError(
                f"{self.source} has no points for leg {leg} (it has legs {list(self.legs)}); "
                "the platform needs errors for all six legs: record every leg."
            ) from None

    def sample_um(self, leg, position_mm, direction, rng):
        x = np.asarray(position_mm, dtype=float).ravel()
        d = np.asarray(direction).ravel()
        meas = np.empty_like(x)
        pred = np.empty_like(x)
        for sign in (1, -1):
            sel = np.flatnonzero(np.where(d >= 0, 1, -1) == sign)
            if sel.size == 0:
                continue
            tab = self._tables[(leg, sign)]
            n_pass = tab.passes_um.shape[0]
            pick = rng.integers(0, n_pass, size=sel.size)
            if self.measurement == "mean":
                meas[sel] = np.interp(x[sel], tab.grid_mm, tab.passes_um.mean(axis=0))
            else:
                meas[sel] = _interp_rows(tab.grid_mm, tab.passes_um[pick], x[sel])
            if self.predicted_um is not None:
                pred[sel] = np.asarray(self.predicted_um(leg, x[sel], np.full(sel.size, sign)), dtype=float)
            else:
                others = (tab.passes_um.sum(axis=0)[None, :] - tab.passes_um[pick]) / (n_pass - 1)
                pred[sel] = _interp_rows(tab.grid_mm, others, x[sel])
        shape = np.shape(position_mm)
        return meas.reshape(shape), pred.reshape(shape)


@dataclass(frozen=True)
class Workspace:
    """Box of random poses about the home pose: +/- `xy_mm` in x and y, +/- `z_mm` in z,
    +/- `tilt_rad` in rx and ry, +/- `yaw_rad` in rz (0 by default: the paper's third angle is
    not used by a secondary-mirror positioner). Poses with a leg outside its stroke or outside
    the error source's positions are redrawn."""

    xy_mm: float = 60.0
    z_mm: float = 60.0
    tilt_rad: float = float(np.radians(3.0))
    yaw_rad: float = 0.0

    def to_json(self) -> dict:
        return {"xy_mm": self.xy_mm, "z_mm": self.z_mm, "tilt_rad": self.tilt_rad, "yaw_rad": self.yaw_rad}


def random_poses(
    geometry: Geometry,
    n: int,
    rng: np.random.Generator,
    workspace: Workspace = Workspace(),
    position_range_mm: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """`n` random poses (n, 6) uniform in the workspace box, every leg within its stroke and
    within `position_range_mm` ((6, 2) per leg, mm from mid-stroke) when given. Returns the poses
    and how many were drawn to find them. Raises InputError when under 1 % are reachable."""
    half = np.array([workspace.xy_mm, workspace.xy_mm, workspace.z_mm, workspace.tilt_rad, workspace.tilt_rad, workspace.yaw_rad])
    if np.any(half < 0) or not np.all(np.isfinite(half)):
        raise InputError(f"workspace half-ranges must be finite and >= 0, got {workspace}.")
    accepted: list[np.ndarray] = []
    have = 0
    drawn = 0
    while have < n:
        batch = max(256, 2 * (n - have))
        poses = geometry.home_pose_mm_rad + rng.uniform(-1.0, 1.0, size=(batch, 6)) * half
        lengths = inverse_kinematics(geometry, poses)
        ok = np.all(in_stroke(geometry, lengths), axis=1)
        if position_range_mm is not None:
            pos = leg_positions_mm(geometry, lengths)
            ok &= np.all((pos >= position_range_mm[:, 0]) & (pos <= position_range_mm[:, 1]), axis=1)
        hits = np.flatnonzero(ok)
        if have + hits.size >= n:
            # count draws only up to the n-th reachable pose, so drawn/n is the rejection rate
            hits = hits[: n - have]
            drawn += int(hits[-1]) + 1
        else:
            drawn += batch
        accepted.append(poses[hits])
        have += hits.size
        if drawn >= 100 * max(n, 256) and have < 0.01 * drawn:
            raise InputError(
                f"only {have} of {drawn} random poses keep every leg within its stroke and the recorded positions; "
                "shrink the workspace (--xy-mm, --z-mm, --tilt-deg) or record over a longer stroke."
            )
    return np.concatenate(accepted), drawn


def approach_directions(positions_mm: np.ndarray, start_mm: np.ndarray | None = None) -> np.ndarray:
    """Direction (+1/-1) each leg approaches its position with, visiting the rows in order.

    `positions_mm` (N, 6). The tour starts at `start_mm` (default mid-stroke, 0) heading +1;
    a leg whose position does not change keeps its previous direction.
    """
    pos = np.asarray(positions_mm, dtype=float)
    prev = np.vstack([np.zeros((1, pos.shape[1])) if start_mm is None else np.atleast_2d(start_mm), pos[:-1]])
    step = np.sign(pos - prev)
    out = np.empty(pos.shape, dtype=np.int8)
    last = np.ones(pos.shape[1], dtype=np.int8)
    for i in range(pos.shape[0]):
        last = np.where(step[i] != 0, step[i], last).astype(np.int8)
        out[i] = last
    return out


def _pose_error(fk_poses: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    err = fk_poses - nominal
    err[:, :3] *= 1000.0  # mm -> um
    return err


@dataclass(frozen=True, eq=False)
class ExperimentResult:
    """Arrays are (N poses, 6). Leg arrays: columns legs 1-6, um. Pose error arrays: columns
    POSE_ERROR_FIELDS (x, y, z um; rx, ry, rz rad), NaN where FK failed (see fk_status_*)."""

    geometry: Geometry
    poses_mm_rad: np.ndarray
    leg_positions_mm: np.ndarray
    directions: np.ndarray
    leg_error_um: np.ndarray
    leg_predicted_um: np.ndarray
    pose_error: np.ndarray
    pose_error_compensated: np.ndarray
    fk_status: np.ndarray
    fk_status_compensated: np.ndarray
    drawn: int
    seed: int
    workspace: Workspace
    source: str
    contributions: np.ndarray = field(repr=False)  # (N, 6 components, 6 legs) original errors
    contributions_compensated: np.ndarray = field(repr=False)

    @property
    def leg_compensated_um(self) -> np.ndarray:
        return self.leg_error_um - self.leg_predicted_um

    @property
    def valid(self) -> np.ndarray:
        """Poses where both FK solves converged (the ones the statistics use)."""
        return (self.fk_status == FkStatus.CONVERGED) & (self.fk_status_compensated == FkStatus.CONVERGED)


def run_experiment(
    geometry: Geometry,
    errors: LegErrorSampler,
    poses: int = 1000,
    seed: int = 0,
    workspace: Workspace = Workspace(),
    tol_mm: float = 1e-10,
) -> ExperimentResult:
    """Run the paper's experiment on `poses` random poses (see the module docstring).

    `errors` gives measured and predicted leg errors; FK stops at `tol_mm` (leg length
    residual, mm): 1e-10 mm is four orders below the um errors studied, as the paper asks of
    its solver (an order of magnitude at least).
    """
    if poses < 1:
        raise InputError(f"--poses must be at least 1, got {poses}.")
    rng = np.random.default_rng(seed)
    ranges = np.array([errors.position_range_mm(leg) for leg in range(1, 7)], dtype=float)
    nominal, drawn = random_poses(geometry, poses, rng, workspace, ranges)
    lengths = inverse_kinematics(geometry, nominal)
    positions = leg_positions_mm(geometry, lengths)
    directions = approach_directions(positions)
    meas = np.empty_like(positions)
    pred = np.empty_like(positions)
    for i in range(6):
        meas[:, i], pred[:, i] = errors.sample_um(i + 1, positions[:, i], directions[:, i], rng)
    if not (np.all(np.isfinite(meas)) and np.all(np.isfinite(pred))):
        raise InputError(f"{errors.description}: the error source returned non-finite errors.")
    # FK from the nominal pose: the erroneous pose is a few um away, two Newton steps
    fk = forward_kinematics(geometry, lengths + meas / 1000.0, initial_poses_mm_rad=nominal, tol_mm=tol_mm, check_stroke=False)
    fkc = forward_kinematics(geometry, lengths + (meas - pred) / 1000.0, initial_poses_mm_rad=nominal, tol_mm=tol_mm, check_stroke=False)
    return ExperimentResult(
        geometry=geometry,
        poses_mm_rad=nominal,
        leg_positions_mm=positions,
        directions=directions,
        leg_error_um=meas,
        leg_predicted_um=pred,
        pose_error=_pose_error(fk.poses_mm_rad, nominal),
        pose_error_compensated=_pose_error(fkc.poses_mm_rad, nominal),
        fk_status=fk.status,
        fk_status_compensated=fkc.status,
        drawn=drawn,
        seed=seed,
        workspace=workspace,
        source=errors.description,
        contributions=pose_error_contributions(geometry, nominal, meas),
        contributions_compensated=pose_error_contributions(geometry, nominal, meas - pred),
    )


def _stats(orig: np.ndarray, comp: np.ndarray) -> dict:
    r0 = float(np.max(orig) - np.min(orig))
    r1 = float(np.max(comp) - np.min(comp))
    return {
        "max_original": float(np.max(orig)),
        "min_original": float(np.min(orig)),
        "max_compensated": float(np.max(comp)),
        "min_compensated": float(np.min(comp)),
        "range_original": r0,
        "range_compensated": r1,
        "range_reduction_pct": 100.0 * (1.0 - r1 / r0) if r0 > 0 else None,
        "mean_abs_original": float(np.mean(np.abs(orig))),
        "mean_abs_compensated": float(np.mean(np.abs(comp))),
    }


MEASUREMENT_LABELS = {
    "mean": "systematic error (mean of the recorded passes)",
    "pass": "one recorded pass (leg repeatability included)",
}
"""What each `RecordedLegErrors.measurement` means, for reports."""


def reduction_digest(summary: dict, measured: str | None = None) -> dict:
    """The range reductions of a `summarize` result, for setting two runs side by side (same seed,
    so same poses, another measurement): pose components and pooled legs with the acceptance
    flags, each leg's reduction, and the common/differential split."""
    cm = summary["common_mode"]
    return {
        "measured": measured,
        "label": MEASUREMENT_LABELS.get(measured or "", measured),
        "source": summary["source"],
        "leg_range_reduction_pct": summary["legs"]["all"]["range_reduction_pct"],
        "per_leg_range_reduction_pct": {k: v["range_reduction_pct"] for k, v in summary["legs"].items() if k != "all"},
        "acceptance": summary["acceptance"],
        "common_range_reduction_pct": cm["common"]["range_reduction_pct"],
        "differential_range_reduction_pct": cm["differential"]["range_reduction_pct"],
        "common_share_of_variance_pct": [cm["common_share_of_variance_pct"], cm["compensated_common_share_of_variance_pct"]],
    }


def run_measurements(
    geometry: Geometry,
    errors: LegErrorSampler,
    other_errors: LegErrorSampler | None = None,
    poses: int = 1000,
    seed: int = 0,
    workspace: Workspace = Workspace(),
) -> tuple[ExperimentResult, dict]:
    """Run the experiment with `errors` and, when `other_errors` is given, again with it on the
    same poses and directions (same seed: only the measurement differs). Returns the first run
    and its `summarize` with `measured` (the first source's measurement, None for a source
    without one) and, with `other_errors`, `other_measurement` (its `reduction_digest`): what
    `station platform` and the terminal UI's Platform page report."""
    result = run_experiment(geometry, errors, poses=poses, seed=seed, workspace=workspace)
    summary = summarize(result)
    summary["measured"] = getattr(errors, "measurement", None)
    if other_errors is not None:
        other = summarize(run_experiment(geometry, other_errors, poses=poses, seed=seed, workspace=workspace))
        summary["other_measurement"] = reduction_digest(other, getattr(other_errors, "measurement", None))
    return result, summary


def summarize(result: ExperimentResult) -> dict:
    """The paper's Tables 1 and 2 for this run, as JSON-able data.

    `pose`: one entry per POSE_ERROR_FIELDS component (x/y/z in um, angles in rad) with max/min
    original and compensated error, ranges, range reduction % and mean |error|; angles also as
    `*_arcsec` entries. `legs`: the same per leg (um) and pooled over all legs (`all`).
    `dominant_leg`: per component, the leg with the largest mean |linearised contribution|,
    before and after compensation. `acceptance`: each component's range reduction against the
    pooled leg error range reduction. `common_mode`: the legs' mean (common part) and the
    deviations from it (differential part), before and after, with the common part's share of
    the variance. `fk`: FK status counts.
    """
    ok = result.valid
    if not ok.any():
        raise InputError("forward kinematics failed on every pose; nothing to summarise.")
    pose = {}
    for k, name in enumerate(POSE_ERROR_FIELDS):
        pose[name] = _stats(result.pose_error[ok, k], result.pose_error_compensated[ok, k])
        if k >= 3:
            pose[name.replace("_rad", "_arcsec")] = _stats(result.pose_error[ok, k] * ARCSEC_PER_RAD, result.pose_error_compensated[ok, k] * ARCSEC_PER_RAD)
    legs = {str(i + 1): _stats(result.leg_error_um[ok, i], result.leg_compensated_um[ok, i]) for i in range(6)}
    legs["all"] = _stats(result.leg_error_um[ok].ravel(), result.leg_compensated_um[ok].ravel())
    from procedures.platform.sensitivity import dominant_legs

    dom = dominant_legs(result.contributions[ok])
    dom_c = dominant_legs(result.contributions_compensated[ok])
    # The linearised map (sensitivity) must reproduce the FK pose error: its worst mismatch
    # relative to the error range says how far the "dominant leg" attribution can be trusted.
    lin = result.contributions[ok].sum(axis=2)
    mismatch = {}
    for k, name in enumerate(POSE_ERROR_FIELDS):
        rng_k = np.ptp(result.pose_error[ok, k])
        mismatch[name] = float(np.max(np.abs(lin[:, k] - result.pose_error[ok, k])) / rng_k) if rng_k > 0 else 0.0
    leg_red = legs["all"]["range_reduction_pct"]
    acceptance = {
        name: {
            "range_reduction_pct": pose[name]["range_reduction_pct"],
            "leg_range_reduction_pct": leg_red,
            "at_least_leg_reduction": (pose[name]["range_reduction_pct"] is not None and leg_red is not None and pose[name]["range_reduction_pct"] >= leg_red),
        }
        for name in POSE_ERROR_FIELDS
    }
    # Common mode (the mean of the six legs at a pose) moves the platform mostly along z; the
    # differences between legs drive x, y and the angles. Alike legs (same manufacturing) put most
    # of the original error in the common part, while what compensation leaves is independent per
    # leg: then x, y and the angles shrink less than the legs do. These figures say how much.
    orig, comp = result.leg_error_um[ok], result.leg_compensated_um[ok]
    common_o, common_c = orig.mean(axis=1), comp.mean(axis=1)
    diff_o, diff_c = orig - common_o[:, None], comp - common_c[:, None]
    total_var = float(np.var(orig - orig.mean()))
    common_mode = {
        "common": _stats(common_o, common_c),
        "differential": _stats(diff_o.ravel(), diff_c.ravel()),
        "common_share_of_variance_pct": (100.0 * float(np.var(common_o)) / total_var) if total_var > 0 else None,
        "compensated_common_share_of_variance_pct": (
            100.0 * float(np.var(common_c)) / float(np.var(comp - comp.mean())) if np.var(comp) > 0 else None),
    }
    statuses = {
        "original": {s.name.lower(): int(np.sum(result.fk_status == s)) for s in FkStatus},
        "compensated": {s.name.lower(): int(np.sum(result.fk_status_compensated == s)) for s in FkStatus},
    }
    return {
        "poses": int(result.poses_mm_rad.shape[0]),
        "poses_used": int(ok.sum()),
        "poses_drawn": int(result.drawn),
        "seed": int(result.seed),
        "workspace": result.workspace.to_json(),
        "source": result.source,
        "pose": pose,
        "legs": legs,
        "dominant_leg": {"original": dom, "compensated": dom_c},
        "linearisation_mismatch_rel": mismatch,
        "acceptance": acceptance,
        "common_mode": common_mode,
        "fk": statuses,
    }


__all__ = [
    "ExperimentResult",
    "FunctionLegErrors",
    "LegErrorFn",
    "LegErrorSampler",
    "MEASUREMENT_LABELS",
    "RecordedLegErrors",
    "Workspace",
    "approach_directions",
    "random_poses",
    "reduction_digest",
    "run_experiment",
    "run_measurements",
    "summarize",
]
