"""Geometry data, closed-form IK and vectorised Newton FK of the Gough-Stewart platform."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from procedures.vocabulary import InputError
from procedures.platform.geometry import (
    DEFAULT_GEOMETRY_PATH,
    GeometryError,
    default_geometry,
    load_geometry,
    triangle_pairs_geometry,
)
from procedures.platform.kinematics import (
    FkStatus,
    forward_kinematics,
    in_stroke,
    inverse_kinematics,
    length_jacobian,
    reachable,
    rotation_matrices,
)


@pytest.fixture(scope="module")
def geo():
    return default_geometry()


def random_poses(geo, n, rng, xyz_mm=50.0, ang_rad=0.05):
    return geo.home_pose_mm_rad + np.column_stack([rng.uniform(-xyz_mm, xyz_mm, (n, 3)), rng.uniform(-ang_rad, ang_rad, (n, 3))])


# -- geometry ---------------------------------------------------------------------------------

def test_default_geometry_has_the_papers_legs_at_home(geo):
    lengths = inverse_kinematics(geo, geo.home_pose_mm_rad)
    assert np.allclose(lengths, 1095.85, atol=1e-9)
    assert np.allclose(geo.stroke_min_mm, -90.0) and np.allclose(geo.stroke_max_mm, 90.0)
    # home height from the documented construction: joints 45 deg apart on 600 mm circles
    horizontal = 2 * 600.0 * math.sin(math.radians(22.5))
    assert geo.home_z_mm == pytest.approx(math.sqrt(1095.85**2 - horizontal**2), abs=1e-6)
    assert np.allclose(geo.home_pose_mm_rad[[0, 1, 3, 4, 5]], 0.0, atol=1e-9)


def test_default_file_is_the_documented_construction(geo):
    made = triangle_pairs_geometry(radius_mm=600.0, pair_half_angle_deg=7.5)
    assert np.allclose(geo.base_joints_mm, made.base_joints_mm, atol=1e-8)
    assert np.allclose(geo.platform_joints_mm, made.platform_joints_mm, atol=1e-8)
    # joints paired: each base joint has a partner 156.6 mm away, and legs of a pair diverge
    pair = np.linalg.norm(geo.base_joints_mm[0] - geo.base_joints_mm[1])
    assert pair == pytest.approx(2 * 600 * math.sin(math.radians(7.5)), rel=1e-9)
    plat_pair_of_leg2 = np.linalg.norm(geo.platform_joints_mm[1] - geo.platform_joints_mm[2])
    assert plat_pair_of_leg2 == pytest.approx(pair, rel=1e-9)  # legs 2 and 3 meet at one platform pair


def test_geometry_round_trips_through_toml(tmp_path, geo):
    path = tmp_path / "g.toml"
    path.write_text(geo.to_toml())
    again = load_geometry(path)
    assert np.allclose(again.base_joints_mm, geo.base_joints_mm, atol=1e-6)
    assert np.allclose(again.home_pose_mm_rad, geo.home_pose_mm_rad, atol=1e-5)


def test_per_leg_mid_stroke_gives_a_home_with_every_leg_at_mid_stroke(tmp_path, geo):
    text = geo.to_toml().replace(
        "mid_stroke_mm = [1095.850000, 1095.850000, 1095.850000, 1095.850000, 1095.850000, 1095.850000]",
        "mid_stroke_mm = [1095.0, 1096.0, 1095.5, 1094.8, 1096.2, 1095.85]",
    )
    path = tmp_path / "uneven.toml"
    path.write_text(text)
    g = load_geometry(path)
    assert np.allclose(inverse_kinematics(g, g.home_pose_mm_rad), [1095.0, 1096.0, 1095.5, 1094.8, 1096.2, 1095.85], atol=1e-9)
    assert abs(g.home_pose_mm_rad[3]) > 1e-6 or abs(g.home_pose_mm_rad[4]) > 1e-6  # uneven legs tilt it


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda t: t.replace('format = "station.platform.geometry/1"', 'format = "other/9"'), ["format"]),
        (lambda t: t.replace("stroke_max_mm", "stroke_top_mm"), ["legs.stroke_max_mm"]),
        (lambda t: t.replace("[joints]", "[joints]\nbase_mm = [[0, 0, 0]]\n[unused]"), ["joints.base_mm", "6 rows"]),
        (lambda t: t.replace("stroke_min_mm = -90.0", "stroke_min_mm = 95.0"), ["stroke_min_mm", "below"]),
        (lambda t: t.replace("mid_stroke_mm = 1095.85", 'mid_stroke_mm = "long"'), ["legs.mid_stroke_mm", "numbers"]),
        (lambda t: t.replace("mid_stroke_mm = 1095.85", "mid_stroke_mm = 100.0"), ["cannot reach"]),
        (lambda t: t + "\n[[[", ["not valid TOML"]),
    ],
)
def test_bad_geometry_files_are_refused_with_file_and_field(tmp_path, edit, words):
    text = DEFAULT_GEOMETRY_PATH.read_text()
    path = tmp_path / "bad.toml"
    path.write_text(edit(text))
    with pytest.raises(GeometryError) as info:
        load_geometry(path)
    msg = str(info.value)
    assert str(path) in msg
    for w in words:
        assert w in msg
    assert isinstance(info.value, InputError)


def test_coinciding_joints_are_refused(tmp_path):
    g = triangle_pairs_geometry()
    text = g.to_toml()
    rows = text.split("platform_mm = [\n")[1].splitlines()
    text = text.replace(rows[1], rows[0])  # platform joint 2 on top of joint 1
    path = tmp_path / "same.toml"
    path.write_text(text)
    with pytest.raises(GeometryError, match="rows 1 and 2 coincide"):
        load_geometry(path)


# -- inverse kinematics -----------------------------------------------------------------------

def test_ik_matches_an_independent_rotation_convention(geo):
    rng = np.random.default_rng(3)
    poses = random_poses(geo, 50, rng, ang_rad=0.3)
    lengths = inverse_kinematics(geo, poses)
    for pose, got in zip(poses, lengths):
        # extrinsic x-y-z rotations = Rz Ry Rx: the documented convention, built by scipy
        rot = Rotation.from_euler("xyz", pose[3:]).as_matrix()
        expect = np.linalg.norm(pose[:3] + geo.platform_joints_mm @ rot.T - geo.base_joints_mm, axis=1)
        assert np.allclose(got, expect, atol=1e-10)
    assert np.allclose(rotation_matrices(poses[:5, 3:]), Rotation.from_euler("xyz", poses[:5, 3:]).as_matrix(), atol=1e-15)
    assert inverse_kinematics(geo, poses[0]).shape == (6,)


def test_jacobian_matches_finite_differences(geo):
    rng = np.random.default_rng(4)
    poses = random_poses(geo, 20, rng, ang_rad=0.3)
    jac = length_jacobian(geo, poses)
    h = 1e-6
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        fd = (inverse_kinematics(geo, poses + d) - inverse_kinematics(geo, poses - d)) / (2 * h)
        assert np.allclose(jac[:, :, k], fd, atol=1e-6), k


# -- forward kinematics -----------------------------------------------------------------------

def test_ik_then_fk_returns_10000_poses_to_1e9_mm_and_1e12_rad(geo):
    rng = np.random.default_rng(2014)
    poses = random_poses(geo, 10_000, rng, xyz_mm=70.0, ang_rad=0.06)
    lengths = inverse_kinematics(geo, poses)
    within = np.all(in_stroke(geo, lengths), axis=1)
    assert 0 < np.sum(~within) < 5000  # the box reaches beyond the stroke, so both kinds occur
    res = forward_kinematics(geo, lengths)
    assert np.array_equal(res.status == FkStatus.CONVERGED, within)
    assert np.array_equal(res.status == FkStatus.OUT_OF_STROKE, ~within)
    assert np.array_equal(reachable(geo, poses), within)
    err = np.abs(res.poses_mm_rad - poses)
    assert err[:, :3].max() < 1e-9
    assert err[:, 3:].max() < 1e-12
    assert np.all(res.residual_mm <= 1e-10)
    assert res.counts()["converged"] == int(within.sum())


def test_unreachable_pose_is_reported_out_of_stroke(geo):
    pose = geo.home_pose_mm_rad + np.array([0, 0, 150.0, 0, 0, 0])  # legs ~ +140 mm, beyond +90
    lengths = inverse_kinematics(geo, pose)
    assert not reachable(geo, pose)
    res = forward_kinematics(geo, lengths)
    assert res.status[0] == FkStatus.OUT_OF_STROKE
    assert not res.ok[0]
    assert np.allclose(res.poses_mm_rad[0], pose, atol=1e-9)  # solved, but flagged


def test_singular_pose_is_reported_not_returned(geo):
    flat = np.zeros(6)  # platform in the base plane: every leg horizontal, z not determined
    lengths = inverse_kinematics(geo, flat)
    at = forward_kinematics(geo, lengths, initial_poses_mm_rad=flat, check_stroke=False)
    assert at.status[0] == FkStatus.SINGULAR and np.all(np.isnan(at.poses_mm_rad[0]))
    from_home = forward_kinematics(geo, lengths, check_stroke=False)
    assert from_home.status[0] in (FkStatus.SINGULAR, FkStatus.NOT_CONVERGED)
    assert np.all(np.isnan(from_home.poses_mm_rad[0]))


def test_impossible_or_bad_lengths_do_not_converge(geo):
    rng = np.random.default_rng(5)
    good = inverse_kinematics(geo, random_poses(geo, 3, rng))
    bad = np.vstack([good, np.full(6, 10.0), [np.nan] * 6])  # 10 mm legs cannot join 600 mm circles
    res = forward_kinematics(geo, bad)
    assert list(res.status[:3]) == [FkStatus.CONVERGED] * 3
    assert res.status[3] in (FkStatus.NOT_CONVERGED, FkStatus.SINGULAR)
    assert res.status[4] == FkStatus.NOT_CONVERGED
    assert np.all(np.isnan(res.poses_mm_rad[3:]))
    assert np.all(np.isfinite(res.poses_mm_rad[:3]))


def test_iteration_limit_reports_not_converged(geo):
    pose = geo.home_pose_mm_rad + np.array([40.0, -30.0, 20.0, 0.05, -0.04, 0.03])
    res = forward_kinematics(geo, inverse_kinematics(geo, pose), max_iterations=1)
    assert res.status[0] == FkStatus.NOT_CONVERGED
    assert np.all(np.isnan(res.poses_mm_rad[0]))
    res = forward_kinematics(geo, inverse_kinematics(geo, pose))
    assert res.status[0] == FkStatus.CONVERGED and res.iterations[0] >= 2


def test_wide_workspace_converges_from_home(geo):
    rng = np.random.default_rng(6)
    poses = random_poses(geo, 2000, rng, xyz_mm=150.0, ang_rad=0.4)
    res = forward_kinematics(geo, inverse_kinematics(geo, poses), check_stroke=False)
    ok = res.status == FkStatus.CONVERGED
    assert ok.mean() > 0.99
    assert np.abs(res.poses_mm_rad[ok] - poses[ok]).max() < 1e-8


def test_fk_reports_the_condition_at_the_returned_pose_whichever_start_path(geo):
    """The common-start first step and the chord steps near the solution (kinematics.CHORD_MM)
    must give the pose and the condition number a fresh Newton solve from each start gives."""
    rng = np.random.default_rng(8)
    poses = random_poses(geo, 300, rng, xyz_mm=60.0, ang_rad=0.05)
    lengths = inverse_kinematics(geo, poses)
    shared = forward_kinematics(geo, lengths, check_stroke=False)
    # per-pose starts (not one common pose): no shared first step
    starts = geo.home_pose_mm_rad + np.column_stack([rng.uniform(-1, 1, (300, 3)), np.zeros((300, 3))])
    own = forward_kinematics(geo, lengths, initial_poses_mm_rad=starts, check_stroke=False)
    assert np.all(shared.status == FkStatus.CONVERGED) and np.all(own.status == FkStatus.CONVERGED)
    assert np.abs(shared.poses_mm_rad - own.poses_mm_rad).max() < 1e-9
    # the condition number at the returned pose, computed independently (numpy's cond, 1-norm)
    jac = length_jacobian(geo, shared.poses_mm_rad)
    jac[:, :, 3:] /= geo.platform_radius_mm
    want = 1.0 / np.linalg.cond(jac, p=1)
    assert np.allclose(shared.rcond, want, rtol=1e-3)
    assert np.allclose(own.rcond, want, rtol=1e-3)
