"""Gough-Stewart platform geometry as data: joint coordinates, mid-stroke lengths, stroke limits.

Frames and units (used by the whole `procedures.platform` package):
- Base frame: fixed to the base plate, z up (towards the moving platform), origin at the centre
  of the base joint circle, millimetres.
- Platform frame: fixed to the moving platform, origin at the centre of its joint circle; at the
  home pose it is the base frame translated by (0, 0, home_z_mm).
- Leg i (1..6) runs from base joint i (spherical joint, base frame) to platform joint i
  (universal joint, platform frame). Leg *length* is the joint-centre distance, mm; the leg
  *position* is length minus the leg's mid-stroke length, mm (the coordinate of the
  recordings and drives: positive = longer, see drivers.interfaces).
- Stroke limits are positions, mm relative to mid-stroke (default -90 .. +90).

Geometry files are TOML (see `geometries/default.toml`); `load_geometry(path)` validates them and
names the file and field when something is wrong.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from procedures.vocabulary import InputError
from procedures.platform.kinematics import FkStatus, forward_kinematics

GEOMETRY_FORMAT = "station.platform.geometry/1"
DEFAULT_GEOMETRY_PATH = Path(__file__).with_name("geometries") / "default.toml"
LEGS = 6


class GeometryError(InputError):
    """A geometry file or value is invalid; the message names the file and field."""


@dataclass(frozen=True, eq=False)
class Geometry:
    """A six-leg Gough-Stewart platform.

    `base_joints_mm` (6, 3): base joint centres in the base frame. `platform_joints_mm` (6, 3):
    platform joint centres in the platform frame. `mid_stroke_mm` (6,): leg length at mid-stroke.
    `stroke_min_mm` / `stroke_max_mm` (6,): travel limits as positions relative to mid-stroke.
    `home_pose_mm_rad` (6,): the pose with every leg at mid-stroke (x, y, z mm; rx, ry, rz rad),
    solved when the geometry is built.
    """

    name: str
    base_joints_mm: np.ndarray
    platform_joints_mm: np.ndarray
    mid_stroke_mm: np.ndarray
    stroke_min_mm: np.ndarray
    stroke_max_mm: np.ndarray
    source: str = "<memory>"
    home_pose_mm_rad: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        where = self.source
        for name in ("base_joints_mm", "platform_joints_mm"):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.shape != (LEGS, 3):
                raise GeometryError(f"{where}: {name} must be 6 rows of [x, y, z] mm, got shape {arr.shape}.")
            if not np.all(np.isfinite(arr)):
                raise GeometryError(f"{where}: {name} holds a non-finite coordinate.")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        for name in ("mid_stroke_mm", "stroke_min_mm", "stroke_max_mm"):
            arr = np.broadcast_to(np.array(getattr(self, name), dtype=float), (LEGS,)).copy()
            if not np.all(np.isfinite(arr)):
                raise GeometryError(f"{where}: {name} holds a non-finite value.")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if np.any(self.mid_stroke_mm <= 0):
            raise GeometryError(f"{where}: mid_stroke_mm must be positive (leg lengths in mm).")
        if np.any(self.stroke_min_mm >= self.stroke_max_mm):
            raise GeometryError(f"{where}: stroke_min_mm must be below stroke_max_mm for every leg.")
        if np.any(self.mid_stroke_mm + self.stroke_min_mm <= 0):
            raise GeometryError(f"{where}: mid_stroke_mm + stroke_min_mm must stay positive (a leg cannot be shorter than zero).")
        for name in ("base_joints_mm", "platform_joints_mm"):
            pts = getattr(self, name)
            gaps = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2) + np.eye(LEGS)
            if np.min(gaps) < 1e-6:
                i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
                raise GeometryError(f"{where}: {name} rows {i + 1} and {j + 1} coincide; every joint needs its own place.")
        if self.home_pose_mm_rad is None:
            object.__setattr__(self, "home_pose_mm_rad", self._solve_home())
        else:
            home = np.array(self.home_pose_mm_rad, dtype=float)
            home.setflags(write=False)
            object.__setattr__(self, "home_pose_mm_rad", home)

    @property
    def platform_radius_mm(self) -> float:
        """Mean distance of the platform joints from the platform origin, mm (the length scale
        that makes angle and position columns of Jacobians comparable)."""
        return float(np.mean(np.linalg.norm(self.platform_joints_mm, axis=1)))

    @property
    def home_z_mm(self) -> float:
        return float(self.home_pose_mm_rad[2])

    def _solve_home(self) -> np.ndarray:
        # Start above the base at the height that gives leg 1 its mid-stroke length when the
        # platform is level and centred, then let forward kinematics settle all six legs.
        d = self.base_joints_mm - self.platform_joints_mm
        horiz2 = d[:, 0] ** 2 + d[:, 1] ** 2
        if np.any(horiz2 >= self.mid_stroke_mm**2):
            raise GeometryError(
                f"{self.source}: a leg at mid-stroke cannot reach from its base joint to its platform joint "
                "(horizontal distance >= mid_stroke_mm); check the joint coordinates."
            )
        z0 = float(np.mean(np.sqrt(self.mid_stroke_mm**2 - horiz2) + d[:, 2]))
        guess = np.array([0.0, 0.0, z0, 0.0, 0.0, 0.0])
        res = forward_kinematics(self, self.mid_stroke_mm, initial_poses_mm_rad=guess, tol_mm=1e-12, check_stroke=False)
        if res.status[0] != FkStatus.CONVERGED:
            raise GeometryError(
                f"{self.source}: no home pose with every leg at mid-stroke was found near the level pose "
                f"z = {z0:.1f} mm ({FkStatus(int(res.status[0])).name.lower()}); check the joint coordinates."
            )
        return res.poses_mm_rad[0]

    def to_toml(self) -> str:
        """The geometry as a TOML document `load_geometry` reads back."""
        def row(v):
            return "[" + ", ".join(f"{x:.6f}" for x in v) + "]"

        lines = [
            f'format = "{GEOMETRY_FORMAT}"',
            f'name = "{self.name}"',
            "",
            "[legs]",
            f"mid_stroke_mm = {row(self.mid_stroke_mm)}",
            f"stroke_min_mm = {row(self.stroke_min_mm)}",
            f"stroke_max_mm = {row(self.stroke_max_mm)}",
            "",
            "[joints]",
            "base_mm = [",
            *[f"  {row(p)}," for p in self.base_joints_mm],
            "]",
            "platform_mm = [",
            *[f"  {row(p)}," for p in self.platform_joints_mm],
            "]",
            "",
        ]
        return "\n".join(lines)


def triangle_pairs_geometry(
    radius_mm: float = 600.0,
    pair_half_angle_deg: float = 7.5,
    mid_stroke_mm: float = 1095.85,
    stroke_half_mm: float = 90.0,
    name: str = "triangle pairs",
) -> Geometry:
    """The paper's kind of positioner: base and platform of the same radius, joints in close pairs.

    Base pairs are centred at 0, 120, 240 degrees, platform pairs at 60, 180, 300 degrees; each
    joint sits `pair_half_angle_deg` either side of its pair centre, so neighbouring legs from one
    base pair go to two different platform pairs and the legs form triangles. Leg 1 runs from the
    base joint at -half to the platform joint at -60 + half, leg 2 from +half to 60 - half, and so
    on around the circle. All legs are `mid_stroke_mm` long at the home pose (level, centred, at
    the height that gives them that length).
    """
    h = pair_half_angle_deg
    base_deg = [-h, h, 120 - h, 120 + h, 240 - h, 240 + h]
    plat_deg = [-60 + h, 60 - h, 60 + h, 180 - h, 180 + h, 300 - h]

    def ring(degs):
        a = np.radians(degs)
        return np.stack([radius_mm * np.cos(a), radius_mm * np.sin(a), np.zeros(LEGS)], axis=1)

    return Geometry(
        name=name,
        base_joints_mm=ring(base_deg),
        platform_joints_mm=ring(plat_deg),
        mid_stroke_mm=np.full(LEGS, mid_stroke_mm),
        stroke_min_mm=np.full(LEGS, -stroke_half_mm),
        stroke_max_mm=np.full(LEGS, stroke_half_mm),
        source=f"triangle_pairs_geometry(radius_mm={radius_mm}, pair_half_angle_deg={pair_half_angle_deg})",
    )


def _field(doc: dict, section: str, key: str, path: str):
    sec = doc.get(section)
    if not isinstance(sec, dict):
        raise GeometryError(f"{path}: missing section [{section}]; see docs/platform.md for the geometry format.")
    if key not in sec:
        raise GeometryError(f"{path}: missing field {section}.{key}; see docs/platform.md for the geometry format.")
    return sec[key]


def _numbers(value, shape: tuple[int, ...], where: str, allow_scalar: bool = False) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError(f"{where} must hold numbers, got {value!r}.") from None
    if allow_scalar and arr.ndim == 0:
        return np.full(shape, float(arr))
    if arr.shape != shape:
        want = "6 numbers (one per leg)" if shape == (LEGS,) else "6 rows of [x, y, z]"
        raise GeometryError(f"{where} must be {want}{' or one number for all legs' if allow_scalar else ''}, got shape {arr.shape}.")
    return arr


def load_geometry(path: str | Path | None = None) -> Geometry:
    """Read a geometry TOML file (the default positioner when `path` is None).

    Fields: `format` ("station.platform.geometry/1"), `name`, `[legs]` `mid_stroke_mm`,
    `stroke_min_mm`, `stroke_max_mm` (6 numbers or one for all legs, mm), `[joints]` `base_mm`
    and `platform_mm` (6 rows of [x, y, z] mm). Raises GeometryError naming file and field.
    """
    p = Path(path) if path is not None else DEFAULT_GEOMETRY_PATH
    where = str(p)
    try:
        with open(p, "rb") as fh:
            doc = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise GeometryError(f"{where}: not valid TOML ({exc}).") from None
    fmt = doc.get("format")
    if fmt != GEOMETRY_FORMAT:
        raise GeometryError(f'{where}: field format must be "{GEOMETRY_FORMAT}", got {fmt!r}.')
    name = str(doc.get("name", p.stem))
    mid = _numbers(_field(doc, "legs", "mid_stroke_mm", where), (LEGS,), f"{where}: legs.mid_stroke_mm", True)
    smin = _numbers(_field(doc, "legs", "stroke_min_mm", where), (LEGS,), f"{where}: legs.stroke_min_mm", True)
    smax = _numbers(_field(doc, "legs", "stroke_max_mm", where), (LEGS,), f"{where}: legs.stroke_max_mm", True)
    base = _numbers(_field(doc, "joints", "base_mm", where), (LEGS, 3), f"{where}: joints.base_mm")
    plat = _numbers(_field(doc, "joints", "platform_mm", where), (LEGS, 3), f"{where}: joints.platform_mm")
    return Geometry(name, base, plat, mid, smin, smax, source=where)


def default_geometry() -> Geometry:
    """The documented default positioner (geometries/default.toml)."""
    return load_geometry(DEFAULT_GEOMETRY_PATH)


def describe(geometry: Geometry) -> str:
    """A few lines on the geometry for reports."""
    pair = np.linalg.norm(geometry.base_joints_mm[0] - geometry.base_joints_mm[1])
    return (
        f"{geometry.name}: base radius {np.mean(np.linalg.norm(geometry.base_joints_mm[:, :2], axis=1)):.1f} mm, "
        f"platform radius {geometry.platform_radius_mm:.1f} mm, joint pair spacing {pair:.1f} mm, "
        f"mid-stroke legs {', '.join(f'{m:.2f}' for m in geometry.mid_stroke_mm)} mm, "
        f"stroke {geometry.stroke_min_mm.min():+.0f}..{geometry.stroke_max_mm.max():+.0f} mm, "
        f"home z {geometry.home_z_mm:.3f} mm"
    )


__all__ = [
    "GEOMETRY_FORMAT",
    "DEFAULT_GEOMETRY_PATH",
    "Geometry",
    "GeometryError",
    "default_geometry",
    "describe",
    "load_geometry",
    "triangle_pairs_geometry",
]
