"""The compiled edge loop agrees with the numpy edge objective: residuals, nearest angles and
the robust normal equations, searched by grid or seeded, at feasible and infeasible poses."""

from dataclasses import replace

import numpy as np
import pytest
from perception_helpers import MODEL, _scene_1080p, poses_near_the_needle

from suture_bt.perception.edge_kernel import edge_normal_equations
from suture_bt.perception.edge_residuals import edge_jacobian, residuals
from suture_bt.perception.fit_solver import FD_STEPS, _irls_weights
from suture_bt.perception.tissue_cut import TissueCut


@pytest.mark.parametrize("loss", ["cauchy", "geman_mcclure"])
def test_kernel_matches_the_numpy_residuals_and_normal_equations(loss):
    rays, T, T6 = poses_near_the_needle()
    r, theta = residuals(T, rays, MODEL)
    dT = (T6 - T[:, None]) / FD_STEPS[None, :, None, None]
    J = edge_jacobian(T, dT, rays, MODEL, theta)
    w = _irls_weights(r, 1.0, loss)
    w = np.where(np.isfinite(w), w, 0.0)
    J = np.where(np.isfinite(J), J, 0.0)
    rr = np.where(np.isfinite(r), r, 0.0)
    A = (J * w[:, None]) @ J.transpose(0, 2, 1)
    g = ((J * w[:, None]) @ rr[..., None])[..., 0]

    rk, thk, csk, Ak, gk = edge_normal_equations(T, T6, FD_STEPS, rays, MODEL, 1.0, loss)
    assert np.array_equal(np.isnan(r), np.isnan(rk))
    assert np.isnan(rk[-1]).all()  # the infeasible pose explains nothing
    np.testing.assert_allclose(rk[:-1], r[:-1], atol=1e-6)  # px
    np.testing.assert_allclose(thk[:-1], theta[:-1], atol=1e-10)
    np.testing.assert_allclose(csk, [np.cos(thk), np.sin(thk)], atol=1e-14)
    scale = np.abs(A).max()
    np.testing.assert_allclose(Ak, A, atol=1e-8 * scale)
    np.testing.assert_allclose(gk, g, atol=1e-8 * np.abs(g).max())
    np.testing.assert_array_equal(Ak, Ak.transpose(0, 2, 1))


def test_seeded_search_matches_and_residuals_alone_leave_the_system_empty():
    rays, T, _ = poses_near_the_needle()
    _, theta = residuals(T, rays, MODEL)
    moved = T.copy()
    moved[:, :3, 3] += 2e-4  # a nearby pose, searched from the previous angles
    r, th = residuals(moved, rays, MODEL, theta_start=theta)
    rk, thk, csk, Ak, gk = edge_normal_equations(
        moved, None, FD_STEPS, rays, MODEL, 1.0, "cauchy", theta
    )
    np.testing.assert_allclose(rk[:-1], r[:-1], atol=1e-6)
    np.testing.assert_allclose(thk[:-1], th[:-1], atol=1e-10)
    np.testing.assert_allclose(csk, [np.cos(thk), np.sin(thk)], atol=1e-14)
    assert not Ak.any() and not gk.any()
    # A coarse grid (the start scoring's) is honoured.
    r12, _ = residuals(T, rays, MODEL, grid=12)
    rk12 = edge_normal_equations(T, None, FD_STEPS, rays, MODEL, 1.0, "cauchy", grid=12)[0]
    np.testing.assert_allclose(rk12[:-1], r12[:-1], atol=1e-6)


def test_kernel_matches_the_numpy_objective_where_the_tissue_cuts_the_needle():
    """A surface plane through the needle at 110° of arc, the base's side below it: rays
    whose nearest arc point is hidden measure to the cut in both, and the cut's motion with
    the pose enters both Jacobians (finite differences of different steps: looser)."""
    rays, T, T6 = poses_near_the_needle()
    T, T6 = T[:-1], T6[:-1]
    st, T_true, *_ = _scene_1080p(7, 0.0)
    theta = np.radians(110.0)
    point = T_true[:3, :3] @ MODEL.point_at(theta) + T_true[:3, 3]
    normal = T_true[:3, :3] @ np.array([np.sin(theta), -np.cos(theta), 0.0])  # to the tip
    rays.cut = TissueCut.from_ports([(point, normal)], np.eye(4), MODEL)
    r, th = residuals(T, rays, MODEL)
    r_whole, th_whole = residuals(T, replace(rays, cut=None), MODEL)
    assert (th != th_whole).mean() > 0.05  # some rays measure to the cut
    dT = (T6 - T[:, None]) / FD_STEPS[None, :, None, None]
    J = edge_jacobian(T, dT, rays, MODEL, th)
    w = _irls_weights(r, 1.0, "cauchy")
    A = (J * w[:, None]) @ J.transpose(0, 2, 1)
    g = ((J * w[:, None]) @ r[..., None])[..., 0]
    rk, thk, _, Ak, gk = edge_normal_equations(T, T6, FD_STEPS, rays, MODEL, 1.0, "cauchy")
    np.testing.assert_allclose(rk, r, atol=1e-6)
    np.testing.assert_allclose(thk, th, atol=1e-10)
    np.testing.assert_allclose(Ak, A, atol=1e-4 * np.abs(A).max())
    np.testing.assert_allclose(gk, g, atol=1e-4 * np.abs(g).max())


def test_the_cut_s_motion_with_the_pose_is_in_the_jacobian():
    """For rays measured to the cut, the analytic derivative (the cut sliding along the arc
    as the pose moves) matches the residuals' finite differences."""
    rays, T, T6 = poses_near_the_needle()
    T, T6 = T[:-1], T6[:-1]
    _, T_true, *_ = _scene_1080p(7, 0.0)
    theta = np.radians(110.0)
    point = T_true[:3, :3] @ MODEL.point_at(theta) + T_true[:3, 3]
    normal = T_true[:3, :3] @ np.array([np.sin(theta), -np.cos(theta), 0.0])
    rays.cut = TissueCut.from_ports([(point, normal)], np.eye(4), MODEL)
    r, th = residuals(T, rays, MODEL)
    _, th_whole = residuals(T, replace(rays, cut=None), MODEL)
    at_cut = th != th_whole
    dT = (T6 - T[:, None]) / FD_STEPS[None, :, None, None]
    J = edge_jacobian(T, dT, rays, MODEL, th)
    r6 = np.stack([residuals(T6[:, j], rays, MODEL)[0] for j in range(6)], 1)
    numeric = (r6 - r[:, None]) / FD_STEPS[None, :, None]
    ok = at_cut[:, None].repeat(6, 1) & np.isfinite(numeric)
    err = np.abs(J - numeric)[ok] / (np.abs(numeric[ok]) + 1.0)
    assert np.median(err) < 1e-3
    without = edge_jacobian(T, dT, replace(rays, cut=None), MODEL, th)  # the cut held still
    err_without = np.abs(without - numeric)[ok] / (np.abs(numeric[ok]) + 1.0)
    assert np.median(err_without) > 10 * np.median(err)
