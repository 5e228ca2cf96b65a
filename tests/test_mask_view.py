"""The fit's view of a mask: its edge points are the pixel midpoints where needle meets
background, in image coordinates, leaving out those against an occluder."""

import numpy as np

from suture_bt.perception.mask_view import MaskView, edge_points


def test_edge_points_are_pixel_midpoints_in_image_coordinates():
    m = np.zeros((5, 6), bool)
    m[2, 3] = True
    pts = edge_points(MaskView(m, (10, 20)))
    expected = {(12.5, 22.0), (13.5, 22.0), (13.0, 21.5), (13.0, 22.5)}
    assert {tuple(p) for p in pts} == expected


def test_edge_points_where_the_mask_meets_an_occluder_are_left_out():
    m = np.zeros((6, 8), bool)
    m[2:4, 1:5] = True  # a 2×4 block; an occluder column right of it
    occ = np.zeros_like(m)
    occ[:, 5] = True
    all_pts = edge_points(MaskView(m, (0, 0)))
    cut = edge_points(MaskView(m, (0, 0), occluder=occ))
    assert len(all_pts) - len(cut) == 2  # the two pairs across the block's right side
    assert not np.any(np.isclose(cut[:, 0], 4.5))
