"""How leg errors map to pose errors: the inverse of the leg-length Jacobian, per pose.

For small leg errors dL (mm) the pose moves by dpose = S dL with S = (dL/dpose)^-1. Rows of S are
pose components (POSE_FIELDS: x, y, z mm; rx, ry, rz rad), columns are legs 1-6. So S[c, i] * e_i
is leg i's share of the error of component c, and the leg with the largest share dominates it.
"""

from __future__ import annotations

import numpy as np

from procedures.platform.geometry import Geometry
from procedures.platform.kinematics import POSE_FIELDS, length_jacobian

ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0
POSE_ERROR_FIELDS = ("x_um", "y_um", "z_um", "rx_rad", "ry_rad", "rz_rad")
"""Pose error components: position errors in micrometres, angle errors in radians."""


def pose_sensitivity(geometry: Geometry, poses_mm_rad) -> np.ndarray:
    """d pose_c / d L_i at each pose: (N, 6, 6) for (N, 6) poses, (6, 6) for one pose.

    Rows are POSE_FIELDS components, columns legs 1-6. Units: mm per mm of leg length for x, y,
    z (equivalently um/um), rad per mm for the angles. NaN where the Jacobian is singular.
    """
    jac = length_jacobian(geometry, poses_mm_rad)
    single = jac.ndim == 2
    jac = jac[None] if single else jac
    out = np.full_like(jac, np.nan)
    finite = np.all(np.isfinite(jac), axis=(1, 2))
    try:
        out[finite] = np.linalg.inv(jac[finite])
    except np.linalg.LinAlgError:
        for i in np.flatnonzero(finite):
            try:
                out[i] = np.linalg.inv(jac[i])
            except np.linalg.LinAlgError:
                pass
    return out[0] if single else out


def pose_error_contributions(geometry: Geometry, poses_mm_rad, leg_error_um) -> np.ndarray:
    """Linearised pose error split by leg: (N, 6 components, 6 legs).

    `leg_error_um` (N, 6): leg length errors, um (measured minus commanded). Entry [n, c, i] is
    leg i's contribution to component c (POSE_ERROR_FIELDS units: um for x, y, z; rad for
    angles). Summing over legs gives the linearised pose error.
    """
    sens = pose_sensitivity(geometry, np.atleast_2d(np.asarray(poses_mm_rad, dtype=float)))
    e = np.atleast_2d(np.asarray(leg_error_um, dtype=float))
    contrib = sens * e[:, None, :]  # um of leg -> um of position; for angles rad/mm * um
    contrib[:, 3:, :] /= 1000.0  # rad per mm times um = 1e-3 rad
    return contrib


def dominant_legs(contributions: np.ndarray) -> list[dict]:
    """Which leg dominates each pose component, by mean |contribution| over the poses.

    `contributions` (N, 6, 6) from `pose_error_contributions` (or a sensitivity matrix (6, 6)).
    Returns one dict per component in POSE_ERROR_FIELDS order: `component`, `leg` (1-6),
    `share_pct` (that leg's share of the summed mean |contribution|), `legs` (every leg within
    1 % of the largest share: symmetric geometries tie), `shares_pct` (all six).
    """
    c = np.abs(np.asarray(contributions, dtype=float))
    if c.ndim == 2:
        c = c[None]
    mean = np.nanmean(c, axis=0)  # (6 components, 6 legs)
    out = []
    for k, name in enumerate(POSE_ERROR_FIELDS):
        total = float(np.sum(mean[k]))
        shares = 100.0 * mean[k] / total if total > 0 else np.zeros(6)
        leg = int(np.argmax(mean[k])) + 1
        ties = [i + 1 for i in range(6) if shares[i] >= 0.99 * shares[leg - 1] and shares[i] > 0]
        out.append({
            "component": name, "leg": leg, "legs": ties, "share_pct": float(shares[leg - 1]),
            "shares_pct": [float(s) for s in shares],
        })
    return out


def sensitivity_report(geometry: Geometry, pose_mm_rad) -> dict:
    """The sensitivity at one pose as JSON-able data: `pose_mm_rad`, `matrix` rows per
    component (`x_um_per_um` ..., `rx_arcsec_per_um` ...), and `dominant` (see dominant_legs)."""
    sens = pose_sensitivity(geometry, np.asarray(pose_mm_rad, dtype=float))
    rows = {}
    for k, name in enumerate(POSE_FIELDS):
        if k < 3:
            rows[name.replace("_mm", "_um_per_um")] = [float(v) for v in sens[k]]
        else:
            rows[name.replace("_rad", "_arcsec_per_um")] = [float(v) * ARCSEC_PER_RAD / 1000.0 for v in sens[k]]
    return {
        "pose_mm_rad": [float(v) for v in np.asarray(pose_mm_rad, dtype=float)],
        "matrix": rows,
        "dominant": dominant_legs(sens),
    }


__all__ = [
    "ARCSEC_PER_RAD",
    "POSE_ERROR_FIELDS",
    "dominant_legs",
    "pose_error_contributions",
    "pose_sensitivity",
    "sensitivity_report",
]
