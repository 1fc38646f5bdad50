"""Forward kinematics speed: the vectorised Newton solver against scipy.optimize.least_squares
pose by pose, in the same run, at equal tolerance.

Both start from the home pose, use the same analytic Jacobian and must bring every leg length
within TOL_MM of the request; the script checks that each did (and how close each pose came back)
before printing poses per second and the ratio.

Rounds of both solvers one after the other (`--rounds`, default 5): the ratio of each side's
best time (its speed on a quiet machine), and the ratio round by round (min, median, max: what
a loaded machine does to it).

    .venv/bin/python bench/bench_fk.py [--poses N] [--scipy-poses M] [--rounds 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import least_squares

from procedures.platform.geometry import default_geometry
from procedures.platform.kinematics import FkStatus, forward_kinematics, inverse_kinematics, length_jacobian

TOL_MM = 1e-10


def workspace_poses(geo, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return geo.home_pose_mm_rad + np.column_stack([rng.uniform(-60, 60, (n, 3)), rng.uniform(-0.05, 0.05, (n, 3))])


def scipy_fk(geo, lengths: np.ndarray, xtol: float) -> tuple[np.ndarray, np.ndarray]:
    """One least_squares (MINPACK LM) solve per pose; returns poses and max |residual| per pose."""
    out = np.empty((lengths.shape[0], 6))
    resid = np.empty(lengths.shape[0])
    start = geo.home_pose_mm_rad
    for i, target in enumerate(lengths):
        sol = least_squares(
            lambda p, t=target: inverse_kinematics(geo, p) - t,
            start,
            jac=lambda p: length_jacobian(geo, p),
            method="lm",
            xtol=xtol, ftol=1e-15, gtol=1e-15,
        )
        out[i] = sol.x
        resid[i] = np.max(np.abs(sol.fun))
    return out, resid


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=20000, help="poses for the vectorised solver")
    ap.add_argument("--scipy-poses", type=int, default=300, help="poses for scipy (one call each)")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of both solvers (default 5); best of them")
    args = ap.parse_args()

    geo = default_geometry()
    poses = workspace_poses(geo, args.poses, seed=1)
    lengths = inverse_kinematics(geo, poses)

    # Equal tolerance: scipy has no leg-residual stop, so use its loosest step tolerance (xtol)
    # at which every pose of a trial set ends within TOL_MM, as the vectorised solver must.
    trial = lengths[:50]
    for xtol in (1e-6, 1e-8, 1e-10, 1e-12, 1e-13, 1e-14):
        if np.all(scipy_fk(geo, trial, xtol)[1] <= TOL_MM):
            break
    sp_poses = poses[: args.scipy_poses]
    # rounds of both, one after the other: a machine whose load changes during the run slows
    # both sides of a round alike; each side's best over the rounds is its unloaded speed
    vec_times, sp_times = [], []
    for _ in range(args.rounds):
        t0 = time.perf_counter()
        res = forward_kinematics(geo, lengths, tol_mm=TOL_MM, check_stroke=False)
        vec_times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        sp, sp_resid = scipy_fk(geo, lengths[: args.scipy_poses], xtol)
        sp_times.append(time.perf_counter() - t0)
    best, sp_best = min(vec_times), min(sp_times)
    ok = res.status == FkStatus.CONVERGED
    vec_rate = args.poses / best
    vec_err = np.abs(res.poses_mm_rad[ok] - poses[ok])
    sp_rate = args.scipy_poses / sp_best
    sp_err = np.abs(sp - sp_poses)
    per_round = sorted((args.poses / v) / (args.scipy_poses / t) for v, t in zip(vec_times, sp_times))

    print(f"forward kinematics, default geometry, tolerance {TOL_MM:g} mm on every leg length")
    print(
        f"  vectorised Newton : {args.poses} poses in {best * 1e3:8.1f} ms = {vec_rate:10.0f} poses/s; "
        f"converged {ok.sum()}/{args.poses}, mean iterations {res.iterations.mean():.2f}, "
        f"max residual {np.nanmax(res.residual_mm):.1e} mm, max pose error {vec_err[:, :3].max():.1e} mm / {vec_err[:, 3:].max():.1e} rad"
    )
    print(
        f"  scipy least_squares (lm, xtol {xtol:g}, pose by pose): {args.scipy_poses} poses in {sp_best * 1e3:8.1f} ms = {sp_rate:10.0f} poses/s; "
        f"within tolerance {(sp_resid <= TOL_MM).sum()}/{args.scipy_poses}, max residual {sp_resid.max():.1e} mm, "
        f"max pose error {sp_err[:, :3].max():.1e} mm / {sp_err[:, 3:].max():.1e} rad"
    )
    print(f"  ratio vectorised / scipy: {vec_rate / sp_rate:.0f}x (best times of {args.rounds} rounds); per round "
          f"min {per_round[0]:.0f}x, median {per_round[len(per_round) // 2]:.0f}x, max {per_round[-1]:.0f}x")


if __name__ == "__main__":
    main()
