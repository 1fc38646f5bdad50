"""Inverse (closed form) and forward (Newton) kinematics of a Gough-Stewart platform, vectorised.

Pose convention (one row of a `poses_mm_rad` array, see POSE_FIELDS):
    x_mm, y_mm, z_mm      the platform frame origin in the base frame, millimetres
    rx_rad, ry_rad, rz_rad  roll-pitch-yaw about the *fixed* base axes, applied X then Y then Z:
                          R = Rz(rz) @ Ry(ry) @ Rx(rx), radians
A platform joint a (platform frame) is at p + R a in the base frame; leg i's length is
|p + R a_i - b_i| (mm). See procedures.platform.geometry for frames and leg numbering.

Forward kinematics is Newton's method on the six leg-length equations with the analytic
Jacobian, run on all poses at once (poses along the last axis), with a backtracking step so a
poor start does not diverge; poses sharing a start take their first step with its one Jacobian,
and poses within CHORD_MM of the solution keep their last Jacobian's inverse (chord steps).
It returns the assembly mode reached from the start pose (the home pose unless given), and a
status per pose instead of a pose it cannot vouch for (see FkStatus).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol

import numpy as np

POSE_FIELDS = ("x_mm", "y_mm", "z_mm", "rx_rad", "ry_rad", "rz_rad")
DEFAULT_TOL_MM = 1e-10  # leg-length residual at which FK stops; far below any leg error (um)
_BLOCK = 4096  # poses per vectorised block (cache-sized)
CHORD_MM = 0.1  # leg residual below which a pose keeps its Jacobian's inverse (chord steps)
DEFAULT_SINGULAR_RCOND = 1e-5  # smallest/largest singular value of the scaled Jacobian;
# below it 1 um of leg error moves the pose by more than 0.1 mm: the pose is not worth reporting


class Joints(Protocol):
    """What the kinematics reads of a platform (procedures.platform.geometry.Geometry is one):
    stated here, not imported, because a Geometry solves its home pose with `forward_kinematics`
    while it is built (the geometry module imports this one)."""

    base_joints_mm: np.ndarray
    platform_joints_mm: np.ndarray
    mid_stroke_mm: np.ndarray
    stroke_min_mm: np.ndarray
    stroke_max_mm: np.ndarray
    home_pose_mm_rad: np.ndarray

    @property
    def platform_radius_mm(self) -> float: ...


class FkStatus(IntEnum):
    """Outcome of forward kinematics for one pose."""

    CONVERGED = 0  # pose solved within tolerance, every leg within its stroke
    OUT_OF_STROKE = 1  # pose solved, but a leg length lies outside its stroke limits
    NOT_CONVERGED = 2  # no solution within max_iterations (or progress stalled); pose is NaN
    SINGULAR = 3  # the Jacobian is singular at the solution or on the way; pose is NaN


@dataclass(frozen=True, eq=False)
class FkResult:
    """Forward kinematics of N poses.

    `poses_mm_rad` (N, 6) in POSE_FIELDS order, NaN where status is NOT_CONVERGED or SINGULAR.
    `status` (N,) FkStatus values. `iterations` (N,) Newton steps taken. `residual_mm` (N,)
    largest |IK length - requested length| at the returned pose (NaN where no pose). `rcond` (N,)
    reciprocal 1-norm condition number of the Jacobian at the returned pose (angle columns
    scaled by the platform radius so they are lengths too).
    """

    poses_mm_rad: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    residual_mm: np.ndarray
    rcond: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """True where the pose is solved and within stroke."""
        return self.status == FkStatus.CONVERGED

    def counts(self) -> dict[str, int]:
        """Number of poses per status name, e.g. {"converged": 998, "singular": 2, ...}."""
        return {s.name.lower(): int(np.sum(self.status == s)) for s in FkStatus}


def _as_poses(poses_mm_rad) -> tuple[np.ndarray, bool]:
    arr = np.asarray(poses_mm_rad, dtype=float)
    single = arr.ndim == 1
    arr = np.atleast_2d(arr)
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise ValueError(f"poses must have 6 columns {POSE_FIELDS}, got shape {np.shape(poses_mm_rad)}")
    return arr, single


def rotation_matrices(angles_rad) -> np.ndarray:
    """Rotation matrices (N, 3, 3) for roll-pitch-yaw angles (N, 3): R = Rz(rz) Ry(ry) Rx(rx)."""
    return _rotations(np.atleast_2d(np.asarray(angles_rad, dtype=float)))


def _rotations(angles: np.ndarray):
    """R (N, 3, 3) for roll-pitch-yaw angles (N, 3)."""
    return np.moveaxis(np.array(_rotation_parts(angles.T)[0]).reshape(3, 3, -1), -1, 0)


def _rotation_parts(angles_t: np.ndarray):
    """The nine entries of R, row by row, each an (N,) array, for angles (3, N); and the
    nonzero entries (-sin rz, cos rz) of w_1, the base-frame axis of the ry rate (w_0, the
    axis of rx, is R's first column, w_2, the axis of rz, is e_z): dR/d(angle k) = [w_k]x R,
    so the angle columns of the Jacobian are cross products."""
    ca, sa = np.cos(angles_t[0]), np.sin(angles_t[0])
    cb, sb = np.cos(angles_t[1]), np.sin(angles_t[1])
    cc, sc = np.cos(angles_t[2]), np.sin(angles_t[2])
    sbsa, sbca = sb * sa, sb * ca
    r = (cc * cb, cc * sbsa - sc * ca, cc * sbca + sc * sa,
         sc * cb, sc * sbsa + cc * ca, sc * sbca - cc * sa,
         -sb, cb * sa, cb * ca)
    return r, (-sc, cc)


def _legs_t(geometry: Joints, poses_t: np.ndarray, jacobian: bool):
    """Leg lengths (6 legs, N) for poses (6 components, N) and, if asked, the Jacobian
    dL/dpose as (N, 6 legs, 6 components). Poses along the last axis: every operation is on
    contiguous (6, N) arrays and no reduction runs over a short axis (2-3x faster than
    (N, 6) rows)."""
    (r00, r01, r02, r10, r11, r12, r20, r21, r22), (w10, w11) = _rotation_parts(poses_t[3:])
    a = geometry.platform_joints_mm[:, :, None]  # (6, 3, 1): broadcasts against (N,)
    b = geometry.base_joints_mm[:, :, None]
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    rax = r00 * ax + r01 * ay + r02 * az  # R a_i, (6, N) per component
    ray = r10 * ax + r11 * ay + r12 * az
    raz = r20 * ax + r21 * ay + r22 * az
    lx = rax + (poses_t[0] - b[:, 0])
    ly = ray + (poses_t[1] - b[:, 1])
    lz = raz + (poses_t[2] - b[:, 2])
    lengths = np.sqrt(lx * lx + ly * ly + lz * lz)
    if not jacobian:
        return lengths, None
    inv = 1.0 / lengths
    ux, uy, uz = lx * inv, ly * inv, lz * inv
    mx = ray * uz - raz * uy  # R a x u, written out: np.cross is slow on small axes
    my = raz * ux - rax * uz
    mz = rax * uy - ray * ux
    jt = np.empty((6, 6, lengths.shape[1]))  # (component, leg, pose)
    jt[0], jt[1], jt[2] = ux, uy, uz
    # dL/d(angle k) = u . (w_k x R a) = w_k . (R a x u)
    jt[3] = mx * r00 + my * r10 + mz * r20
    jt[4] = mx * w10 + my * w11
    jt[5] = mz
    return lengths, jt.transpose(2, 1, 0)


def _legs(geometry: Joints, poses: np.ndarray, jacobian: bool):
    """Leg lengths (N, 6) and, if asked, the Jacobian dL/dpose (N, 6 legs, 6 pose components)."""
    lengths, jac = _legs_t(geometry, poses.T, jacobian)
    return lengths.T, (None if jac is None else np.ascontiguousarray(jac))


def inverse_kinematics(geometry: Joints, poses_mm_rad) -> np.ndarray:
    """Leg lengths, mm, for poses (N, 6) or one pose (6,) in POSE_FIELDS order. Closed form.

    Returns (N, 6) lengths (joint-centre distances, leg i in column i-1), or (6,) for one pose.
    Does not check the stroke: see `in_stroke` / `reachable`.
    """
    poses, single = _as_poses(poses_mm_rad)
    lengths = _legs(geometry, poses, jacobian=False)[0]
    return lengths[0] if single else lengths


def length_jacobian(geometry: Joints, poses_mm_rad) -> np.ndarray:
    """dL_i / dpose_c, (N, 6, 6) (or (6, 6) for one pose): rows legs, columns POSE_FIELDS.

    Units: mm/mm for the x, y, z columns, mm/rad for the angle columns.
    """
    poses, single = _as_poses(poses_mm_rad)
    jac = _legs(geometry, poses, jacobian=True)[1]
    return jac[0] if single else jac


def leg_positions_mm(geometry: Joints, lengths_mm) -> np.ndarray:
    """Leg positions relative to mid-stroke (the drives' and recordings' coordinate), mm."""
    return np.asarray(lengths_mm, dtype=float) - geometry.mid_stroke_mm


def in_stroke(geometry: Joints, lengths_mm) -> np.ndarray:
    """True per leg (same shape as `lengths_mm`) where the length is within the stroke limits."""
    pos = leg_positions_mm(geometry, lengths_mm)
    return (pos >= geometry.stroke_min_mm) & (pos <= geometry.stroke_max_mm)


def reachable(geometry: Joints, poses_mm_rad) -> np.ndarray:
    """True per pose where every leg length (by IK) lies within its stroke."""
    lengths = np.atleast_2d(inverse_kinematics(geometry, poses_mm_rad))
    ok = np.all(in_stroke(geometry, lengths), axis=1)
    return ok[0] if np.ndim(poses_mm_rad) == 1 else ok


def _inverses(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """J^-1 per pose (N, 6, 6) and a mask of those that could be inverted (the others NaN)."""
    try:
        return np.linalg.inv(jac), np.ones(jac.shape[0], dtype=bool)
    except np.linalg.LinAlgError:
        # one bad matrix spoils the batch: one pose at a time (rare)
        inv = np.full_like(jac, np.nan)
        ok = np.zeros(jac.shape[0], dtype=bool)
        for i in range(jac.shape[0]):
            try:
                inv[i] = np.linalg.inv(jac[i])
                ok[i] = True
            except np.linalg.LinAlgError:
                pass
        return inv, ok


def _rcond(geometry: Joints, jac: np.ndarray, inv: np.ndarray | None = None, ok: np.ndarray | None = None) -> np.ndarray:
    """Reciprocal 1-norm condition number 1 / (|J|_1 |J^-1|_1) of the scaled Jacobian, 0 where
    J cannot be inverted. Angle columns are divided by the platform radius: a small rotation
    moves the joints by about radius * angle, so the scaled columns are all lengths.
    `inv`, `ok`: J^-1 of the unscaled Jacobian when already known (_inverses)."""
    if inv is None:
        inv, ok = _inverses(jac)
    radius = geometry.platform_radius_mm
    # scaled J = J diag(1, 1, 1, 1/r, 1/r, 1/r), so its inverse is diag(1, 1, 1, r, r, r) J^-1
    norm = np.maximum(np.abs(jac[:, :, :3]).sum(axis=1).max(axis=1), np.abs(jac[:, :, 3:]).sum(axis=1).max(axis=1) / radius)
    a_inv = np.abs(inv)
    norm_inv = (a_inv[:, :3].sum(axis=1) + a_inv[:, 3:].sum(axis=1) * radius).max(axis=1)
    out = np.zeros(jac.shape[0])
    good = ok & np.isfinite(norm_inv) & (norm_inv > 0)
    out[good] = 1.0 / (norm[good] * norm_inv[good])
    return out


def _newton_steps(jac: np.ndarray, residual: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve jac @ step = -residual per pose; (steps, singular mask). Exactly singular or
    non-finite systems give singular=True and a zero step."""
    steps = np.zeros_like(residual)
    singular = ~np.all(np.isfinite(jac), axis=(1, 2))
    good = ~singular
    try:
        steps[good] = np.linalg.solve(jac[good], -residual[good][..., None])[..., 0]
    except np.linalg.LinAlgError:
        # one bad matrix spoils the batch: fall back to one pose at a time (rare)
        for i in np.flatnonzero(good):
            try:
                steps[i] = np.linalg.solve(jac[i], -residual[i])
            except np.linalg.LinAlgError:
                singular[i] = True
    singular |= ~np.all(np.isfinite(steps), axis=1)
    steps[singular] = 0.0
    return steps, singular


def forward_kinematics(
    geometry: Joints,
    lengths_mm,
    initial_poses_mm_rad=None,
    tol_mm: float = DEFAULT_TOL_MM,
    max_iterations: int = 50,
    singular_rcond: float = DEFAULT_SINGULAR_RCOND,
    check_stroke: bool = True,
) -> FkResult:
    """Poses for leg lengths (N, 6) or (6,), mm, by Newton's method with the analytic Jacobian.

    `initial_poses_mm_rad`: start pose(s), (6,) or (N, 6); default the home pose. The result is
    the solution reached from there (the assembly mode nearest the start). A pose counts as
    solved when every leg length is within `tol_mm` of the request; SINGULAR when the scaled
    Jacobian's reciprocal condition number is below `singular_rcond` (or a Newton system is
    singular); NOT_CONVERGED after `max_iterations` or when backtracking finds no decrease.
    With `check_stroke`, solved poses whose lengths lie outside the stroke are OUT_OF_STROKE
    (their pose is still returned). The result always has N rows (FkResult).
    """
    lengths = np.asarray(lengths_mm, dtype=float)
    if lengths.ndim == 1:
        lengths = lengths[None]
    if lengths.ndim != 2 or lengths.shape[1] != 6:
        raise ValueError(f"lengths_mm must have 6 columns (legs 1-6), got shape {np.shape(lengths_mm)}")
    n = lengths.shape[0]
    start = geometry.home_pose_mm_rad if initial_poses_mm_rad is None else initial_poses_mm_rad
    starts = np.broadcast_to(np.asarray(start, dtype=float), (n, 6))
    if n <= _BLOCK:
        return _fk_block(geometry, lengths, starts, tol_mm, max_iterations, singular_rcond, check_stroke)
    # Blocks of a few thousand poses keep the temporaries in cache: 20 000 poses at once run
    # at half the rate of the same poses in blocks.
    parts = [
        _fk_block(geometry, lengths[i:i + _BLOCK], starts[i:i + _BLOCK], tol_mm, max_iterations, singular_rcond, check_stroke)
        for i in range(0, n, _BLOCK)
    ]
    return FkResult(*(np.concatenate([getattr(r, f) for r in parts]) for f in ("poses_mm_rad", "status", "iterations", "residual_mm", "rcond")))


def _shared_start_inverse(geometry, starts: np.ndarray) -> np.ndarray | None:
    """J^-1 at the start pose when every pose starts from the same one (the home pose by
    default), else None: the first Newton step of all of them then needs one 6x6 inverse
    instead of one solve per pose. None too when that Jacobian is singular or ill-conditioned
    (the per-pose path then reports it)."""
    if starts.shape[0] < 2 or starts.strides[0] != 0 and not np.all(starts == starts[0]):
        return None
    _, jac = _legs(geometry, starts[:1], jacobian=True)
    if not np.all(np.isfinite(jac)) or not _rcond(geometry, jac)[0] >= DEFAULT_SINGULAR_RCOND:
        return None
    return np.linalg.inv(jac[0])


def _fk_block(geometry, lengths, starts, tol_mm, max_iterations, singular_rcond, check_stroke) -> FkResult:
    # Poses along the last axis (see _legs_t): x (6 components, n), residuals (6 legs, n).
    n = lengths.shape[0]
    target = np.ascontiguousarray(lengths.T)
    x = np.array(starts.T)
    status = np.full(n, FkStatus.NOT_CONVERGED, dtype=np.int8)
    iterations = np.zeros(n, dtype=np.int32)

    residual = _legs_t(geometry, x, jacobian=False)[0] - target
    err = np.abs(residual).max(axis=0)
    live = np.isfinite(target).all(axis=0) & np.isfinite(x).all(axis=0) & ~(err <= tol_mm)
    start_inv = _shared_start_inverse(geometry, starts)
    # Near the solution the Jacobian hardly changes over the remaining steps: a pose within
    # CHORD_MM keeps the inverse of its last Jacobian for the steps left (chord steps: one
    # small product each, no new Jacobian or solve), and the condition number comes from that
    # inverse (within a Newton step, < CHORD_MM, of the returned pose) instead of a last one.
    inv_last = np.empty((n, 6, 6))
    rcond = np.full(n, np.nan)
    have_inv = np.zeros(n, dtype=bool)
    for it in range(max_iterations):
        idx = np.flatnonzero(live)
        if idx.size == 0:
            break
        x0 = x[:, idx]
        r0 = residual[:, idx]
        norm0 = np.einsum("in,in->n", r0, r0)
        step = np.empty_like(r0)
        singular = np.zeros(idx.size, dtype=bool)
        chord = have_inv[idx]
        if it == 0 and start_inv is not None:
            # every pose is at the common start: one Jacobian for all (same step as below)
            step[:] = -(start_inv @ r0)
        else:
            if chord.any():
                step[:, chord] = -np.einsum("nij,jn->in", inv_last[idx[chord]], r0[:, chord])
            near = ~chord & (err[idx] < CHORD_MM)
            if near.any():
                k = idx[near]
                _, jac = _legs_t(geometry, x0[:, near], jacobian=True)
                jac_ok = np.isfinite(jac).all(axis=(1, 2))
                inv, ok = _inverses(np.where(jac_ok[:, None, None], jac, 0.0))
                ok &= jac_ok & np.isfinite(inv).all(axis=(1, 2))
                inv_last[k] = inv
                rcond[k] = _rcond(geometry, jac, inv, ok)
                have_inv[k] = ok
                step[:, near] = -np.einsum("nij,jn->in", inv, r0[:, near])
                singular[near] = ~ok
            far = ~chord & ~near
            if far.any():
                _, jac = _legs_t(geometry, x0[:, far], jacobian=True)
                far_step, singular[far] = _newton_steps(jac, r0[:, far].T)
                step[:, far] = far_step.T
        step[:, singular] = 0.0
        status[idx[singular]] = FkStatus.SINGULAR
        live[idx[singular]] = False
        iterations[idx] += 1

        # Backtracking: halve the step until the squared residual decreases (Newton's direction
        # is a descent direction for it); near the solution the full step is always taken.
        t = np.ones(idx.size)
        x1 = x0 + step
        r1 = _legs_t(geometry, x1, jacobian=False)[0] - target[:, idx]
        norm1 = np.einsum("in,in->n", r1, r1)
        worse = ~singular & ~(norm1 < norm0) & ~(np.abs(r1).max(axis=0) <= tol_mm)
        # a chord step that does not help is not halved: the pose takes a fresh Newton step next
        chord_failed = worse & chord
        have_inv[idx[chord_failed]] = False
        worse &= ~chord
        for _half in range(30):
            if not worse.any():
                break
            w = np.flatnonzero(worse)
            t[w] *= 0.5
            x1[:, w] = x0[:, w] + t[w] * step[:, w]
            r1[:, w] = _legs_t(geometry, x1[:, w], jacobian=False)[0] - target[:, idx[w]]
            norm1[w] = np.einsum("in,in->n", r1[:, w], r1[:, w])
            worse[w] = ~(norm1[w] < norm0[w]) & ~(np.abs(r1[:, w]).max(axis=0) <= tol_mm)
        stalled = worse  # no decrease even with a tiny step: give up on these poses
        live[idx[stalled]] = False
        moved = ~singular & ~stalled & ~chord_failed
        m = idx[moved]
        x[:, m] = x1[:, moved]
        residual[:, m] = r1[:, moved]
        err[m] = np.abs(r1[:, moved]).max(axis=0)
        live[m[err[m] <= tol_mm]] = False

    poses = np.ascontiguousarray(x.T)
    solved = (err <= tol_mm) & (status != FkStatus.SINGULAR)
    late = solved & ~have_inv  # solved without a Jacobian near the end (or at the start)
    if late.any():
        _, jac = _legs(geometry, poses[late], jacobian=True)
        rcond[late] = _rcond(geometry, jac)
    rcond[~solved] = np.nan
    status[solved] = FkStatus.CONVERGED
    status[solved & ~(rcond >= singular_rcond)] = FkStatus.SINGULAR
    if check_stroke:
        bad_stroke = ~np.all(in_stroke(geometry, lengths), axis=1)
        status[(status == FkStatus.CONVERGED) & bad_stroke] = FkStatus.OUT_OF_STROKE
    no_pose = (status == FkStatus.NOT_CONVERGED) | (status == FkStatus.SINGULAR)
    poses[no_pose] = np.nan
    err = np.where(no_pose, np.nan, err)
    return FkResult(poses_mm_rad=poses, status=status, iterations=iterations, residual_mm=err, rcond=rcond)


__all__ = [
    "DEFAULT_SINGULAR_RCOND",
    "DEFAULT_TOL_MM",
    "FkResult",
    "FkStatus",
    "POSE_FIELDS",
    "forward_kinematics",
    "in_stroke",
    "inverse_kinematics",
    "leg_positions_mm",
    "length_jacobian",
    "reachable",
    "rotation_matrices",
]
