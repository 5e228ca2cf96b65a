"""Stray mask pieces: a detached blob beside the answer's arc is found and taken out; the
needle's own pieces, the swage band and blobs far from the arc are left alone."""

import numpy as np
import pytest
from perception_helpers import stereo
from scipy.spatial.transform import Rotation

from suture_bt.geometry import NeedleModel
from suture_bt.perception.mask_view import MaskView, edge_points
from suture_bt.perception.needle_projection import project_cam, rasterize_needle
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.stray_pieces import (
    edge_point_labels,
    piece_labels,
    refit_without_stray_pieces,
    stray_pieces,
    without,
)
from suture_bt.transforms import make_transform

MODEL = NeedleModel()
STEREO = stereo(1920, 1080)
#: A needle 100 mm in front of the left eye, turned 30 deg from face-on.
T = make_transform(Rotation.from_euler("x", 30, degrees=True).as_matrix(), (0.0, 0.0, 0.1))
GREY, VIOLET = (150, 150, 150), (140, 60, 190)


def _scene(blob_offset_px: float, blob_colour=GREY, eye: int = 0):
    """One eye's image and mask view (``eye`` 0 left, 1 right): the needle cut in two by a
    13 px gap (a jaw across it), and in the gap a 5×5 px blob whose centre is
    ``blob_offset_px`` outside the arc (the lit edge of that jaw's blade, taken for wire)."""
    cam = (STEREO.left, STEREO.right)[eye]
    T_eye = cam.T_cam_world @ STEREO.left.T_world_cam @ T
    mask = rasterize_needle(cam, T_eye, MODEL)
    arc = project_cam(cam, MODEL.centerline(41) @ T_eye[:3, :3].T + T_eye[:3, 3])
    u, v = np.round(arc[12]).astype(int)
    mask[v - 6 : v + 7, u - 6 : u + 7] = False  # the gap
    centre = project_cam(cam, T_eye[:3, 3][None])[0]
    out = (arc[12] - centre) / np.linalg.norm(arc[12] - centre)
    bu, bv = np.round(arc[12] + out * blob_offset_px).astype(int)
    mask[bv - 2 : bv + 3, bu - 2 : bu + 3] = True
    rgb = np.zeros((*mask.shape, 3), np.uint8)
    rgb[mask] = GREY
    rgb[bv - 2 : bv + 3, bu - 2 : bu + 3] = blob_colour
    ys, xs = np.nonzero(mask)
    y0, x0 = ys.min() - 5, xs.min() - 5
    view = MaskView(mask[y0 : ys.max() + 6, x0 : xs.max() + 6], (int(x0), int(y0)))
    return rgb, view


def test_a_blob_beside_the_arc_is_stray_and_the_needles_own_pieces_are_not():
    rgb, view = _scene(blob_offset_px=3.0)
    n, lab = piece_labels(view)
    assert n - 1 == 3  # two pieces of wire and the blob
    stray = stray_pieces(rgb, view, 0, T, STEREO, MODEL, None)
    assert stray.sum() == 25 and len(np.unique(lab[stray])) == 1
    sizes = np.bincount(lab.ravel())[1:]
    wire = [k + 1 for k in np.argsort(sizes)[-2:]]
    assert not any(np.any(stray & (lab == k)) for k in wire)


def test_a_violet_blob_is_the_band_and_a_far_blob_is_ignored():
    rgb, view = _scene(blob_offset_px=3.0, blob_colour=VIOLET)
    assert not stray_pieces(rgb, view, 0, T, STEREO, MODEL, None).any()
    rgb, view = _scene(blob_offset_px=20.0)
    assert not stray_pieces(rgb, view, 0, T, STEREO, MODEL, None).any()


def test_the_right_eye_is_judged_with_its_own_rays():
    rgb, view = _scene(blob_offset_px=3.0, eye=1)
    assert stray_pieces(rgb, view, 1, T, STEREO, MODEL, None).sum() == 25
    # Taken for a left view, the whole outline is the 4 mm baseline's ~30 px of disparity off
    # the answer: nothing is near enough to be judged.
    assert not stray_pieces(rgb, view, 0, T, STEREO, MODEL, None).any()


def test_without_takes_the_pieces_out_and_marks_them_as_occluder():
    rgb, view = _scene(blob_offset_px=3.0)
    stray = stray_pieces(rgb, view, 0, T, STEREO, MODEL, None)
    clean = without(view, stray)
    assert not (clean.mask & stray).any()
    assert clean.occluder[stray].all() and not (clean.occluder & clean.mask).any()
    assert len(edge_points(clean)) < len(edge_points(view))


def test_edge_points_are_labelled_by_their_own_piece():
    _, view = _scene(3.0)
    n, lab = piece_labels(view)
    point_lab = edge_point_labels(lab, edge_points(view), view.origin)
    assert point_lab.min() >= 1 and set(np.unique(point_lab)) == set(range(1, n))


class _Fit:
    T_cam_needle = T


def _refit(views, attempts):
    images = [_scene(3.0, eye=e)[0] for e in (0, 1)]
    return refit_without_stray_pieces(
        images, views, _Fit(), attempts, ("inputs",), STEREO, MODEL, None
    )


def test_the_refit_runs_without_the_stray_pieces_and_only_when_there_are_some():
    calls = []

    def attempts(images, views, *inputs):
        calls.append((views, inputs))
        return "refit"

    views = tuple(_scene(3.0, eye=e)[1] for e in (0, 1))
    got_views, fit = _refit(views, attempts)
    assert fit == "refit" and calls[0][1] == ("inputs",)
    assert all(g.mask.sum() == v.mask.sum() - 25 for g, v in zip(got_views, views, strict=True))
    clean = tuple(_scene(20.0, eye=e)[1] for e in (0, 1))  # the blob off the arc: not stray
    calls.clear()
    got_views, fit = _refit(clean, attempts)
    assert got_views is clean and isinstance(fit, _Fit) and not calls


def test_a_refused_refit_names_the_pieces_it_dropped():
    def attempts(images, views, *inputs):
        raise NeedleNotFound("the seen part leaves the pose loose")

    views = tuple(_scene(3.0, eye=e)[1] for e in (0, 1))
    with pytest.raises(NeedleNotFound, match="25 and 25 px.*leaves the pose loose"):
        _refit(views, attempts)
