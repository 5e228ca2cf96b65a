"""arc_support: a drawn piece of needle is supported where predicted, not 3 mm beside it."""

import cv2
import numpy as np
import pytest

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import CameraModel, StereoCameraModel
from suture_bt.perception.arc_evidence import arc_support
from suture_bt.perception.colour_refine import ColourRule
from suture_bt.transforms import make_transform, rpy_to_matrix

W, H = 640, 480
TISSUE = (220, 140, 135)
METAL = (150, 150, 155)
NEEDLE = NeedleModel()
#: The piece drawn and asked about: from the tip 70° back along the arc.
PIECE = np.linspace(NEEDLE.tip_angle, NEEDLE.tip_angle + np.deg2rad(70.0), 40)


def _stereo(T_world_frame: np.ndarray) -> StereoCameraModel:
    """Two eyes 4 mm apart along the frame's x, OpenCV convention (z forward)."""
    eyes = [
        CameraModel.from_fov(W, H, 1.2, T_world_frame @ make_transform(None, (s * 0.002, 0, 0)))
        for s in (-1.0, 1.0)
    ]
    return StereoCameraModel(*eyes)


T_FRAME = make_transform(rpy_to_matrix((0.2, -0.3, 0.7)), (0.01, -0.02, 0.03))
STEREO = _stereo(T_FRAME)
#: Needle 100 mm in front, its plane turned 30° from face-on.
T_NEEDLE = T_FRAME @ make_transform(rpy_to_matrix((np.pi + 0.5, 0.1, 0.4)), (0.004, -0.003, 0.1))


def _draw(T_world_needle: np.ndarray, angles=PIECE, thickness: int = 3, seed: int = 0):
    """Left and right RGB images: pink tissue (with a little noise) and the grey polyline."""
    rng = np.random.default_rng(seed)
    pts = NEEDLE.point_at(angles) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
    images = []
    for cam in (STEREO.left, STEREO.right):
        img = np.empty((H, W, 3), np.uint8)
        img[:] = TISSUE
        img = np.clip(img + rng.integers(-4, 5, img.shape), 0, 255).astype(np.uint8)
        uv = np.rint(cam.project(pts)).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [uv], False, METAL, thickness)
        images.append(img)
    return images[0], images[1]


def _shifted(T: np.ndarray, d_cam) -> np.ndarray:
    """T translated by ``d_cam`` (m) given in the left camera's frame."""
    out = T.copy()
    out[:3, 3] += STEREO.left.T_world_cam[:3, :3] @ np.asarray(d_cam, float)
    return out


@pytest.fixture(scope="module")
def images():
    return _draw(T_NEEDLE)


def test_drawn_piece_projects_inside_both_images():
    pts = NEEDLE.point_at(PIECE) @ T_NEEDLE[:3, :3].T + T_NEEDLE[:3, 3]
    for cam in (STEREO.left, STEREO.right):
        uv = cam.project(pts)
        assert np.all((uv >= 20) & (uv < [W - 20, H - 20]))
        assert np.all(cam.to_camera(pts)[:, 2] > 0.09)


def test_drawn_piece_is_supported(images):
    left, right = arc_support(images, STEREO, T_NEEDLE, NEEDLE, PIECE)
    assert left >= 0.9 and right >= 0.9


def test_middle_of_the_piece_is_supported(images):
    inner = PIECE[5:-5]
    assert min(arc_support(images, STEREO, T_NEEDLE, NEEDLE, inner)) >= 0.9


def _across_piece() -> np.ndarray:
    """Unit direction (left camera frame, image plane) across the piece's chord."""
    ends = NEEDLE.point_at(PIECE[[0, -1]]) @ T_NEEDLE[:3, :3].T + T_NEEDLE[:3, 3]
    chord = np.diff(STEREO.left.to_camera(ends), axis=0)[0]
    across = np.cross(chord, [0.0, 0.0, 1.0])
    return across / np.linalg.norm(across)


@pytest.mark.parametrize("side", [1.0, -1.0])
@pytest.mark.parametrize("tilt_deg", [0.0, 25.0])
def test_pose_shifted_3mm_is_not_supported(images, side, tilt_deg):
    """3 mm across the piece (≈ 10 px at 100 mm): neither eye supports it. (A shift along the
    piece's own chord slides the arc along itself and is partly supported, by nature.)"""
    across = _across_piece()
    along = np.cross([0.0, 0.0, 1.0], across)
    t = np.deg2rad(tilt_deg)
    d = 0.003 * side * (np.cos(t) * across + np.sin(t) * along)
    left, right = arc_support(images, STEREO, _shifted(T_NEEDLE, d), NEEDLE, PIECE)
    assert left <= 0.1 and right <= 0.1, (left, right)


def test_pose_shifted_1mm_is_still_supported(images):
    """Within the reach (4 px ≈ 1.1 mm at 100 mm) a small error is tolerated."""
    d = 0.0007 * _across_piece()
    assert min(arc_support(images, STEREO, _shifted(T_NEEDLE, d), NEEDLE, PIECE)) >= 0.9


def test_undrawn_rest_of_needle_is_not_supported(images):
    """The part of the arc that was not drawn (buried, say) is not seen."""
    rest = np.linspace(NEEDLE.tip_angle + np.deg2rad(85.0), NEEDLE.base_angle, 30)
    assert max(arc_support(images, STEREO, T_NEEDLE, NEEDLE, rest)) <= 0.1


def test_blank_tissue_gives_no_support():
    blank = _draw(T_NEEDLE, angles=PIECE[:0])
    assert arc_support(blank, STEREO, T_NEEDLE, NEEDLE, PIECE) == (0.0, 0.0)


def test_points_outside_the_image_count_as_unseen():
    """A piece straddling the left border: no error, the samples outside count as unseen."""
    pts = NEEDLE.point_at(PIECE) @ T_NEEDLE[:3, :3].T + T_NEEDLE[:3, 3]
    uv = STEREO.left.project(pts)
    z = STEREO.left.to_camera(pts)[:, 2].mean()
    u_mid = 0.5 * (uv[:, 0].min() + uv[:, 0].max())
    T_out = _shifted(T_NEEDLE, (-u_mid * z / STEREO.left.fx, 0.0, 0.0))
    uv_out = STEREO.left.project(NEEDLE.point_at(PIECE) @ T_out[:3, :3].T + T_out[:3, 3])
    inside = (np.rint(uv_out[:, 0]) >= 0) & (np.rint(uv_out[:, 0]) < W)
    assert 0.2 < inside.mean() < 0.8
    left, _ = arc_support(_draw(T_out), STEREO, T_out, NEEDLE, PIECE)
    assert left == pytest.approx(inside.mean(), abs=0.1)
    assert left < 0.9


def test_pose_entirely_outside_the_image(images):
    far = _shifted(T_NEEDLE, (0.5, -0.4, 0.0))
    assert arc_support(images, STEREO, far, NEEDLE, PIECE) == (0.0, 0.0)


def test_no_angles_gives_zero(images):
    assert arc_support(images, STEREO, T_NEEDLE, NEEDLE, np.array([])) == (0.0, 0.0)


def test_support_per_eye_is_independent(images):
    """Blanking the right image leaves the left share and zeroes the right one."""
    blank = np.empty_like(images[1])
    blank[:] = TISSUE
    left, right = arc_support((images[0], blank), STEREO, T_NEEDLE, NEEDLE, PIECE)
    assert left >= 0.9 and right == 0.0


def test_a_dim_frame_still_supports_the_drawn_piece(images):
    # At 0.25 x the light the metal's level (38) is under the nominal rule's floor (40); the
    # frame's exposure rule scales its limits down: the piece is seen where it is drawn, and
    # not 3 mm across it.
    dim = tuple(np.rint(img * 0.25).astype(np.uint8) for img in images)
    nominal = arc_support(dim, STEREO, T_NEEDLE, NEEDLE, PIECE, rule=ColourRule())
    assert max(nominal) <= 0.1
    left, right = arc_support(dim, STEREO, T_NEEDLE, NEEDLE, PIECE)
    assert left >= 0.9 and right >= 0.9
    beside = arc_support(dim, STEREO, _shifted(T_NEEDLE, 0.003 * _across_piece()), NEEDLE, PIECE)
    assert max(beside) <= 0.1
