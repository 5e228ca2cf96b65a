"""Shared scene helpers for the perception tests: synthetic ones (no simulator), and the
needle benchmark's task scenes rendered in the simulator (:func:`task_scene`)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import CameraModel, StereoCameraModel
from suture_bt.perception import pose_fit
from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.edge_residuals import edge_rays
from suture_bt.perception.edge_samples import mask_ends
from suture_bt.perception.fit_attempts import FitAttempts
from suture_bt.perception.fit_solver import FD_STEPS
from suture_bt.perception.fit_terms import EndPriorTerm
from suture_bt.perception.mask_view import MaskView, edge_points
from suture_bt.perception.needle_prior import HeldPrior, PortPrior
from suture_bt.perception.needle_projection import (
    params_to_pose,
    pose_to_params,
    project_cam,
    rasterize_needle,
    transform_points,
)
from suture_bt.perception.pose_fit import PoseFitter
from suture_bt.perception.prior_term import HeldPlaceTerm, PriorTerm
from suture_bt.perception.tissue_cut import TissueCut
from suture_bt.transforms import invert, make_transform, pose_to_transform

MODEL = NeedleModel()
#: Tissue pink and needle (and jaw) grey, the colours of the face-on scene's images.
PINK = (200, 110, 110)
GREY = (150, 150, 155)


def stereo(width: int, height: int) -> StereoCameraModel:
    """The SRC endoscope geometry (DESIGN.md §5) built from the core camera model."""
    T_cf = pose_to_transform((0.0, 0.0963, 0.1671), (0.6981, 0.0, -np.pi))
    eyes = [
        CameraModel.from_fov(
            width,
            height,
            1.2,
            T_cf @ make_transform(np.diag([1.0, -1.0, -1.0]), (s * 0.002, 0, -0.05)),
        )
        for s in (-1.0, 1.0)
    ]
    return StereoCameraModel(*eyes)


def random_needle_pose(
    rng: np.random.Generator, zmin: float = 0.08, zmax: float = 0.2
) -> np.ndarray:
    """A needle pose in the left camera frame, in view, 80-200 mm away."""
    z = rng.uniform(zmin, zmax)
    pos = np.array([rng.uniform(-0.25, 0.25) * z, rng.uniform(-0.15, 0.15) * z, z])
    return make_transform(Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix(), pos)


def pose_errors(Ta: np.ndarray, Tb: np.ndarray) -> tuple[float, float]:
    """(position error mm, geodesic angle error deg)."""
    pos = float(np.linalg.norm(Ta[:3, 3] - Tb[:3, 3]) * 1e3)
    ang = float(np.degrees(Rotation.from_matrix(Ta[:3, :3].T @ Tb[:3, :3]).magnitude()))
    return pos, ang


def answer_index(fit) -> int:
    """The row of a fit's candidates that is its answer (found by pose: the cheapest
    candidate need not be the answer, as a prior may choose another)."""
    return next(i for i, P in enumerate(fit.candidates) if np.array_equal(P, fit.T_cam_needle))


def _views(st: StereoCameraModel, T: np.ndarray) -> list[MaskView]:
    """The needle's exact masks at ``T`` (left camera frame) in both eyes, cropped with a
    4-pixel border."""
    T_lr = invert(st.left.T_world_cam) @ st.right.T_world_cam
    views = []
    for cam, Tc in ((st.left, T), (st.right, invert(T_lr) @ T)):
        m = rasterize_needle(cam, Tc, MODEL)
        ys, xs = np.nonzero(m)
        x0, y0 = xs.min() - 4, ys.min() - 4
        views.append(MaskView(m[y0 : ys.max() + 5, x0 : xs.max() + 5], (int(x0), int(y0))))
    return views


def _scene_1080p(seed: int, noise_px: float):
    """Stereo model, a pose 80-120 mm away, its two exact masks and noisy left end pixels."""
    st = stereo(1920, 1080)
    rng = np.random.default_rng(seed)
    T = random_needle_pose(rng, 0.08, 0.12)
    left, right = _views(st, T)
    return st, T, left, right, _ends(st.left, T, rng, noise_px)


def _ends(cam: CameraModel, T: np.ndarray, rng: np.random.Generator, noise_px: float):
    """The needle's base and tip pixels in ``cam`` at ``T``, with Gaussian noise of ``noise_px``."""
    e = project_cam(cam, transform_points(T, np.stack([MODEL.base, MODEL.tip])))
    return e + rng.normal(0, noise_px, e.shape)


def _tip_disc_hidden(view: MaskView, ends, share: float) -> MaskView:
    """The view with a disc of radius ``share`` × the end pixels' distance blanked around
    the tip end (an occluder such as a jaw)."""
    m = view.mask.copy()
    c = ends[1] - np.array(view.origin)
    r = share * np.linalg.norm(ends[1] - ends[0])
    yy, xx = np.mgrid[: m.shape[0], : m.shape[1]]
    m[(xx - c[0]) ** 2 + (yy - c[1]) ** 2 < r**2] = False
    return MaskView(m, view.origin)


def _right_ends(st: StereoCameraModel, T: np.ndarray):
    """The needle's exact base and tip pixels in the right eye (``T`` in the left camera frame)."""
    T_lr = invert(st.left.T_world_cam) @ st.right.T_world_cam
    return project_cam(
        st.right, transform_points(invert(T_lr) @ T, np.stack([MODEL.base, MODEL.tip]))
    )


def _tip_hidden(st, T, left, right, ends):
    """Both eyes' masks with a disc over the tip half (an occluder), and the left hypothesis
    that stops short: base keypoint and the visible piece's far end."""
    er = _right_ends(st, T)
    occ = [_tip_disc_hidden(left, ends, 0.55), _tip_disc_hidden(right, er, 0.55)]
    me = mask_ends(occ[0])
    far = me[int(np.argmax([np.linalg.norm(p - ends[0]) for p in me]))]
    return occ, (ends[0], far), er


def twin_case(monkeypatch):
    """Tip hidden, a misleading alternative and no second search (nor the one run when the
    best pose's ends lie far from the keypoints, since session 40): the unconstrained fit
    without the twin probe answers the tilt-mirror twin (> 10 mm off; see test_pose_fit's
    mirror-twin test; with the probe, session 27's, it finds the needle)."""
    monkeypatch.setattr(pose_fit, "RESEED_MOVED_PX", float("inf"))
    st, T, left, right, ends = _scene_1080p(10, 0.0)
    occ, short, _ = _tip_hidden(st, T, left, right, ends)
    alt = [tuple(ends + np.array([[30.0, 10.0], [-20.0, 25.0]]))]
    kw = dict(alternatives=alt, hidden_end=False)
    return st, T, occ, short, kw


def arc_point(T_world, angle):
    """The needle's arc point at ``angle`` for a needle at ``T_world`` (world frame), for
    placing priors on the wire."""
    return T_world[:3, :3] @ MODEL.point_at(angle) + T_world[:3, 3]


def face_on_scene(occluder: bool = False, background=(0, 0, 0)):
    """A needle 80 mm in front of the left eye, face-on, grey on ``background``; with
    ``occluder`` a grey slab (a jaw) covers the image right of the needle's middle column
    and that part of the wire is left out of the mask."""
    st = stereo(640, 480)
    T = make_transform(np.eye(3), (0.0, 0.0, 0.08))
    imgs, views = [], []
    for cam in (st.left, st.right):
        T_eye = invert(cam.T_world_cam) @ st.left.T_world_cam @ T
        img = np.zeros((cam.height, cam.width, 3), np.uint8)
        img[:] = background
        m = rasterize_needle(cam, T_eye, MODEL)
        img[m] = GREY
        if occluder:
            col = int(np.median(np.nonzero(m)[1]))
            img[:, col:] = GREY
            m[:, col:] = False
        imgs.append(img)
        views.append(MaskView(m))
    return st, T, tuple(imgs), tuple(views)


def images_with_cover(st, full, seen, px: int = 6):
    """Grey needle pixels on black, and over each eye's hidden wire (full minus seen mask)
    a grey cover ``px`` wider (a jaw just over the tip)."""
    import cv2

    out = []
    for f, v in zip(full, seen, strict=True):
        img = np.zeros((st.left.height, st.left.width, 3), np.uint8)
        x0, y0 = f.origin
        h, w = f.mask.shape
        hidden = np.zeros(img.shape[:2], np.uint8)
        hidden[y0 : y0 + h, x0 : x0 + w] = f.mask
        sx, sy = v.origin
        sh, sw = v.mask.shape
        vis = np.zeros(img.shape[:2], bool)
        vis[sy : sy + sh, sx : sx + sw] = v.mask
        hidden[vis] = 0
        cover = cv2.dilate(hidden, np.ones((2 * px + 1, 2 * px + 1), np.uint8)).astype(bool)
        img[cover | vis] = GREY
        out.append(img)
    return tuple(out)


def poses_near_the_needle(n: int = 24):
    """Rays of a 1080p needle's outline, and poses (with their stepped poses) scattered about
    it, the last one infeasible (NaN)."""
    st, T, left, right, _ = _scene_1080p(7, 0.0)
    rays = edge_rays(st, edge_points(left)[::3], edge_points(right)[::3])
    x = pose_to_params(T[None], st.left, MODEL)
    x = x + np.random.default_rng(0).normal(0, [2, 2, 2, 2, 0.05, 0.2], (n, 6))
    x[-1, 4] = -1.0  # infeasible
    steps = np.concatenate([np.zeros((1, 6)), np.diag(FD_STEPS)])
    P = params_to_pose(x[:, None] + steps[None], st.left, MODEL)
    return rays, np.ascontiguousarray(P[:, 0]), P[:, 1:]


def lm_problem(cut: bool):
    """A 1080p needle's edge rays (optionally cut by a surface plane at 110° of arc), starts
    scattered about it, and the fit's terms: keypoints, a held place, a port."""
    st, T, left, right, _ = _scene_1080p(7, 0.0)
    rays = edge_rays(st, edge_points(left)[::3], edge_points(right)[::3])
    if cut:
        theta = np.radians(110.0)
        point = T[:3, :3] @ MODEL.point_at(theta) + T[:3, 3]
        normal = T[:3, :3] @ np.array([np.sin(theta), -np.cos(theta), 0.0])
        rays.cut = TissueCut.from_ports([(point, normal)], np.eye(4), MODEL)
    rng = np.random.default_rng(1)
    x = pose_to_params(T[None], st.left, MODEL) + rng.normal(0, [2, 2, 2, 2, 0.05, 0.2], (8, 6))
    ends = np.stack([MODEL.base, MODEL.tip])
    kps = [project_cam(c, transform_points(c.T_cam_world @ st.left.T_world_cam @ T, ends))
           for c in (st.left, st.right)]  # fmt: skip
    T_world = st.left.T_world_cam @ T
    a = MODEL.tip_angle + 0.6
    pinch, port = arc_point(T_world, a), arc_point(T_world, a + 0.8)
    priors = [HeldPrior("psm1", pinch, 0.001, arc_angle=a), PortPrior("exit1", port, 0.003)]
    keypoints = EndPriorTerm(st, MODEL, (kps[0][:1] + 1.5, kps[1]))
    place = HeldPlaceTerm(priors, st.left.T_cam_world, MODEL)
    points = PriorTerm(priors, st.left.T_cam_world, MODEL)
    return st, rays, x, [keypoints, place, points]


def attempts_with_gates(st, **gates) -> FitAttempts:
    """The fit stage with these gates changed from the defaults."""
    return FitAttempts(st, MODEL, ColourRule(), PoseFitter(st, MODEL), AnswerGates(**gates))


def clean_outline_args(seed: int = 7):
    """A 1080p needle's exact masks on black images, its true end pixels as keypoints."""
    st, T, left, right, ends = _scene_1080p(seed, 0.0)
    images = tuple(np.zeros((1080, 1920, 3), np.uint8) for _ in range(2))
    kp = np.stack([ends, ends])
    score = np.full((2, 2), 0.9)
    return st, T, (images, (left, right), tuple(ends), None, 2.0, None, kp, score)


def task_scene(name: str, i: int, seed: int = 6173, masks: bool = False):
    """Development scene ``i`` of the needle benchmark's set ``name`` (seed 6173, the tuning
    seed, by default) rendered in the simulator: (stereo model, left, right, true T_cam_needle, task
    priors, the phantom's tissue model; with ``masks``, the needle's true masks too)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import needle_pose
    import needle_random_scenes
    import needle_task_scenes

    from suture_bt.datagen.needle_data import SimScene
    from suture_bt.perception.unseen_arc import phantom_tissue
    from suture_bt.transforms import invert

    sim = SimScene(1920, 1080)
    try:
        rng = np.random.default_rng([seed, needle_pose.SETS.index(name), i])
        if name in needle_task_scenes.BUILDERS:
            s, priors = needle_task_scenes.BUILDERS[name](sim, rng)
            sim.apply(s)
            left, mask_left = sim.render("left", s, rng)
        else:  # the random sets (unoccluded, occluded): no task priors, no left mask
            s, left, _, _ = needle_random_scenes.draw_scene(sim, name, rng, i)
            priors, mask_left = [], None
        right, mask_right = sim.render("right", s, rng)
        ph = sim.world.task.phantom
        eye = sim.stereo.left.T_world_cam[:3, 3]
        tissue = phantom_tissue(ph, eye)
        T_true = invert(sim.stereo.left.T_world_cam) @ s.T_world_needle
        out = (sim.stereo, left, right, T_true, priors, tissue)
        return (*out, (mask_left, mask_right)) if masks else out
    finally:
        sim.close()


def recorded_fit(name: str):
    """A pose fit the localiser once made, recorded in ``fixtures/needle_fits/<name>.npz``:
    a fitter at 1920×1080 with the call's depth range and, where the record holds the
    phantom's pose, that phantom's tissue solid (the localiser's), the call's arguments (masks
    with their occluders, keypoints or None) and keyword arguments (depth hint, alternatives, end
    priors, whether an end may be hidden; a NaN depth hint is none), and the needle's true pose
    (left camera)."""
    from pathlib import Path

    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.geometry.tissue_surface import solid_pieces
    from suture_bt.perception.mask_view import MaskView
    from suture_bt.perception.pose_fit import PoseFitter

    d = np.load(Path(__file__).parent / "fixtures" / "needle_fits" / f"{name}.npz")

    def view(eye: str) -> MaskView:
        occluder = d[f"{eye}_occluder"] if f"{eye}_occluder" in d else None
        origin = tuple(int(v) for v in d[f"{eye}_origin"])
        return MaskView(d[f"{eye}_mask"], origin, occluder=occluder)

    fitter = PoseFitter(stereo(1920, 1080), NeedleModel())
    fitter.depth_range = tuple(float(v) for v in d["depth_range"])
    if "T_world_phantom" in d:
        fitter.tissue_solid = solid_pieces(PhantomModel(d["T_world_phantom"]))
    kwargs = dict(
        depth_hint=None if np.isnan(d["depth_hint"]) else float(d["depth_hint"]),
        alternatives=[tuple(a) for a in d["alternatives"]],
        end_priors=(d["end_priors_left"], d["end_priors_right"]),
        hidden_end=bool(d["hidden_end"]),
    )
    return (
        fitter,
        (view("left"), view("right"), tuple(d["keypoints"]) if "keypoints" in d else None),
        kwargs,
        d["T_cam_needle_true"],
    )
