"""Inverse (closed form) and forward (Newton) kinematics of a Gough-Stewart platform, vectorised.

Pose convention (one row of a `poses_mm_rad` array, see POSE_FIELDS):
    x_mm, y_mm, z_mm      the platform frame origin in the base frame, millimetres
    rx_rad, ry_rad, rz_rad  roll-pitch-yaw about the *fixed* base axes, applied X then Y then Z:
                          R = Rz(rz) @ Ry(ry) @ Rx(rx), radians
A platform joint a (platform frame) is at p + R a in the base frame; leg i's length is
|p + R a_i - b_i| (mm). See procedures.platform.geometry for frames and leg numbering.

Forward kinematics is Newton's method on the six leg-length equations with the analytic
Jacobian, run on all poses at once, with a backtracking step so a poor start does not diverge.
It returns the assembly mode reached from the start pose (the home pose unless given), and a
status per pose instead of a pose it cannot vouch for (see FkStatus).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from procedures.platform.geometry import Geometry

POSE_FIELDS = ("x_mm", "y_mm", "z_mm", "rx_rad", "ry_rad", "rz_rad")
DEFAULT_TOL_MM = 1e-10  # leg-length residual at which FK stops; far below any leg error (um)
_BLOCK = 4096  # poses per vectorised block (cache-sized)
DEFAULT_SINGULAR_RCOND = 1e-5  # smallest/largest singular value of the scaled Jacobian;
# below it 1 um of leg error moves the pose by more than 0.1 mm: the pose is not worth reporting


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
    return _rotations(np.atleast_2d(np.asarray(angles_rad, dtype=float)))[0]


def _rotations(angles: np.ndarray):
    """R (N, 3, 3) and W (N, 3, 3), whose columns are the base-frame axes of the three angle
    rates: dR/d(angle k) = [W[:, :, k]]x R, so the angle columns of the Jacobian are cross
    products (cheaper than differentiating R three times)."""
    ca, sa = np.cos(angles[:, 0]), np.sin(angles[:, 0])
    cb, sb = np.cos(angles[:, 1]), np.sin(angles[:, 1])
    cc, sc = np.cos(angles[:, 2]), np.sin(angles[:, 2])
    r = np.empty(angles.shape[:1] + (3, 3))
    r[:, 0, 0] = cc * cb
    r[:, 0, 1] = cc * sb * sa - sc * ca
    r[:, 0, 2] = cc * sb * ca + sc * sa
    r[:, 1, 0] = sc * cb
    r[:, 1, 1] = sc * sb * sa + cc * ca
    r[:, 1, 2] = sc * sb * ca - cc * sa
    r[:, 2, 0] = -sb
    r[:, 2, 1] = cb * sa
    r[:, 2, 2] = cb * ca
    w = np.zeros_like(r)
    w[:, :, 0] = r[:, :, 0]  # rx turns about Rz Ry e_x, the first column of R
    w[:, 0, 1] = -sc  # ry turns about Rz e_y
    w[:, 1, 1] = cc
    w[:, 2, 2] = 1.0  # rz turns about the fixed z axis
    return r, w


def _legs(geometry: Geometry, poses: np.ndarray, jacobian: bool):
    """Leg lengths (N, 6) and, if asked, the Jacobian dL/dpose (N, 6 legs, 6 pose components)."""
    n = poses.shape[0]
    r, w = _rotations(poses[:, 3:])
    # Arrays are (N, 3 components, 6 legs) so the joint transform is one 2-D product
    # (N*3, 3) @ (3, 6), much faster than N small matmuls.
    ra = (r.reshape(n * 3, 3) @ geometry.platform_joints_mm.T).reshape(n, 3, 6)  # R a_i
    legs = ra + (poses[:, :3, None] - geometry.base_joints_mm.T[None])
    lengths = np.sqrt(np.sum(legs * legs, axis=1))
    if not jacobian:
        return lengths, None
    u = legs / lengths[:, None, :]
    m = np.empty_like(u)  # R a x u, written out: np.cross is slow on small axes
    m[:, 0] = ra[:, 1] * u[:, 2] - ra[:, 2] * u[:, 1]
    m[:, 1] = ra[:, 2] * u[:, 0] - ra[:, 0] * u[:, 2]
    m[:, 2] = ra[:, 0] * u[:, 1] - ra[:, 1] * u[:, 0]
    jac = np.empty((n, 6, 6))
    jac[:, :, :3] = u.transpose(0, 2, 1)
    # dL/d(angle k) = u . (w_k x R a) = w_k . (R a x u)
    jac[:, :, 3:] = np.matmul(m.transpose(0, 2, 1), w)
    return lengths, jac


def inverse_kinematics(geometry: Geometry, poses_mm_rad) -> np.ndarray:
    """Leg lengths, mm, for poses (N, 6) or one pose (6,) in POSE_FIELDS order. Closed form.

    Returns (N, 6) lengths (joint-centre distances, leg i in column i-1), or (6,) for one pose.
    Does not check the stroke: see `in_stroke` / `reachable`.
    """
    poses, single = _as_poses(poses_mm_rad)
    lengths = _legs(geometry, poses, jacobian=False)[0]
    return lengths[0] if single else lengths


def length_jacobian(geometry: Geometry, poses_mm_rad) -> np.ndarray:
    """dL_i / dpose_c, (N, 6, 6) (or (6, 6) for one pose): rows legs, columns POSE_FIELDS.

    Units: mm/mm for the x, y, z columns, mm/rad for the angle columns.
    """
    poses, single = _as_poses(poses_mm_rad)
    jac = _legs(geometry, poses, jacobian=True)[1]
    return jac[0] if single else jac


def leg_positions_mm(geometry: Geometry, lengths_mm) -> np.ndarray:
    """Leg positions relative to mid-stroke (the drives' and recordings' coordinate), mm."""
    return np.asarray(lengths_mm, dtype=float) - geometry.mid_stroke_mm


def in_stroke(geometry: Geometry, lengths_mm) -> np.ndarray:
    """True per leg (same shape as `lengths_mm`) where the length is within the stroke limits."""
    pos = leg_positions_mm(geometry, lengths_mm)
    return (pos >= geometry.stroke_min_mm) & (pos <= geometry.stroke_max_mm)


def reachable(geometry: Geometry, poses_mm_rad) -> np.ndarray:
    """True per pose where every leg length (by IK) lies within its stroke."""
    lengths = np.atleast_2d(inverse_kinematics(geometry, poses_mm_rad))
    ok = np.all(in_stroke(geometry, lengths), axis=1)
    return ok[0] if np.ndim(poses_mm_rad) == 1 else ok


def _rcond(geometry: Geometry, jac: np.ndarray) -> np.ndarray:
    """Reciprocal 1-norm condition number 1 / (|J|_1 |J^-1|_1) of the scaled Jacobian, 0 where
    J cannot be inverted. Angle columns are divided by the platform radius: a small rotation
    moves the joints by about radius * angle, so the scaled columns are all lengths."""
    scaled = jac.copy()
    scaled[:, :, 3:] /= geometry.platform_radius_mm
    out = np.zeros(jac.shape[0])
    try:
        inv = np.linalg.inv(scaled)
        ok = np.ones(jac.shape[0], dtype=bool)
    except np.linalg.LinAlgError:
        inv = np.full_like(scaled, np.nan)
        ok = np.zeros(jac.shape[0], dtype=bool)
        for i in range(jac.shape[0]):
            try:
                inv[i] = np.linalg.inv(scaled[i])
                ok[i] = True
            except np.linalg.LinAlgError:
                pass
    norm = np.abs(scaled).sum(axis=1).max(axis=1)
    norm_inv = np.abs(inv).sum(axis=1).max(axis=1)
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
    geometry: Geometry,
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


def _fk_block(geometry, lengths, starts, tol_mm, max_iterations, singular_rcond, check_stroke) -> FkResult:
    n = lengths.shape[0]
    poses = np.array(starts)
    status = np.full(n, FkStatus.NOT_CONVERGED, dtype=np.int8)
    iterations = np.zeros(n, dtype=np.int32)

    residual = _legs(geometry, poses, jacobian=False)[0] - lengths
    err = np.max(np.abs(residual), axis=1)
    live = np.all(np.isfinite(lengths), axis=1) & np.all(np.isfinite(poses), axis=1) & ~(err <= tol_mm)
    for _ in range(max_iterations):
        idx = np.flatnonzero(live)
        if idx.size == 0:
            break
        x0 = poses[idx]
        r0 = residual[idx]
        norm0 = np.einsum("ij,ij->i", r0, r0)
        _, jac = _legs(geometry, x0, jacobian=True)
        step, singular = _newton_steps(jac, r0)
        status[idx[singular]] = FkStatus.SINGULAR
        live[idx[singular]] = False
        iterations[idx] += 1

        # Backtracking: halve the step until the squared residual decreases (Newton's direction
        # is a descent direction for it); near the solution the full step is always taken.
        t = np.ones(idx.size)
        x1 = x0 + step
        r1 = _legs(geometry, x1, jacobian=False)[0] - lengths[idx]
        norm1 = np.einsum("ij,ij->i", r1, r1)
        worse = ~singular & ~(norm1 < norm0) & ~(np.max(np.abs(r1), axis=1) <= tol_mm)
        for _half in range(30):
            if not worse.any():
                break
            w = np.flatnonzero(worse)
            t[w] *= 0.5
            x1[w] = x0[w] + t[w, None] * step[w]
            r1[w] = _legs(geometry, x1[w], jacobian=False)[0] - lengths[idx[w]]
            norm1[w] = np.einsum("ij,ij->i", r1[w], r1[w])
            worse[w] = ~(norm1[w] < norm0[w]) & ~(np.max(np.abs(r1[w]), axis=1) <= tol_mm)
        stalled = worse  # no decrease even with a tiny step: give up on these poses
        live[idx[stalled]] = False
        moved = ~singular & ~stalled
        poses[idx[moved]] = x1[moved]
        residual[idx[moved]] = r1[moved]
        err[idx[moved]] = np.max(np.abs(r1[moved]), axis=1)
        live[idx[moved & (err[idx] <= tol_mm)]] = False

    solved = (err <= tol_mm) & (status != FkStatus.SINGULAR)
    rcond = np.full(n, np.nan)
    if solved.any():
        _, jac = _legs(geometry, poses[solved], jacobian=True)
        rcond[solved] = _rcond(geometry, jac)
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
