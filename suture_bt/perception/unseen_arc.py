"""Is the unseen part of a fitted needle hidden by something? (issue 14 item 4)

The fit's edge objective is one-sided (mask → model): a part of the model arc that no mask
pixel is near costs nothing, which is what lets an occluded needle be fitted at all. It also
lets a wrong hypothesis (the tilt-mirror twin of a partly hidden needle, a pose slid along its
own circle) put its unexplained part anywhere. A real needle is grey metal, bright against the
pink tissue and the dark cavity: where the model puts wire and the image shows neither needle
nor anything that could be in front of it, the hypothesis is wrong.

Each centre-line sample of a pose is projected into each eye and classed:

- *seen*: within the wire's half width (+ slack) of that eye's needle mask;
- *hidden*: outside the image (the border), or within reach of grey metal that is not the
  needle (a jaw or shaft in front), or where the caller's knowledge of the phantom says the
  tissue may hide it (``inside_tissue``: :func:`tissue_model` — below the tissue top or in
  the ridge under a port pair; or the ports the needle is in, from its port priors);
- *exposed*: anything else: tissue or background where a needle in front would show.

The longest run of samples exposed in an eye, as arc length, is the evidence: a few samples at
a mask's ragged end are noise, a run of millimetres is wire that is not there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z, TISSUE_X, TISSUE_Y
from suture_bt.geometry.tissue_surface import solid_pieces
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.colour_refine import ColourRule, needle_coloured, tissue_coloured
from suture_bt.perception.mask_view import MaskView
from suture_bt.perception.small_blobs import without_small_blobs

#: Centre-line samples (over the whole arc, about 0.35 mm apart).
N_SAMPLES = 64
#: Slack (px) beyond the wire's half width within which a sample counts as on the mask.
SEEN_SLACK_PX = 2.0
#: Reach (px, beyond the half width) of grey non-needle pixels that may hide a sample.
HIDER_SLACK_PX = 3.0
#: Border margin (px): samples this close to the image edge count as hidden by it.
BORDER_PX = 2
#: Grey blobs smaller than this many squares of the wire's width (px²) hide nothing (unless
#: cut by the window's edge, where their size is unknown): too small to hide a piece of wire,
#: they are sensor noise in dim tissue. In a held-out report frame at light gain 0.33 (90509673
#: `held_presented` #1 without priors, 2.5 mm / 14.4° off), such specks, 1-3 % of the pixels,
#: hid the answer's 2-4 mm of arc over bare tissue in the left eye; with this, that answer is
#: refused and no other of 977 cached development calls changes its verdict.
MIN_HIDER_SQUARES = 1.0

SEEN, HIDDEN, EXPOSED = 0, 1, 2
#: Depth (m) under the known tissue surface beyond which a seen sample contradicts the pose.
DEEP = 0.0015


@dataclass(frozen=True)
class ArcExposure:
    """Per eye (left, right): each sample's class, the longest exposed run (m of arc) and the
    exposed run that reaches an end of the arc (m; an end put where nothing is seen)."""

    classes: tuple[np.ndarray, np.ndarray]
    longest_exposed: tuple[float, float]
    end_exposed: tuple[float, float] = (0.0, 0.0)
    #: Arc (m) seen in both eyes although the pose puts it deep inside the tissue (more than
    #: ``DEEP`` under its surface), where the tissue would hide it: the pose is wrong.
    seen_inside: float = 0.0
    #: All exposed samples of each eye together (m of arc), runs or not.
    total_exposed: tuple[float, float] = (0.0, 0.0)
    #: All seen samples of each eye together (m of arc): how much of the arc the image shows.
    seen: tuple[float, float] = (0.0, 0.0)

    @property
    def worst(self) -> float:
        """The longer of the two eyes' exposed runs (m)."""
        return float(max(self.longest_exposed))

    @property
    def both(self) -> float:
        """The shorter of the two eyes' exposed runs (m): wire missing in both eyes."""
        return float(min(self.longest_exposed))

    @property
    def both_total(self) -> float:
        """The smaller of the two eyes' total exposed arc (m), runs or not."""
        return float(min(self.total_exposed))


def _longest_run(flags: np.ndarray) -> int:
    best = run = 0
    for f in flags:
        run = run + 1 if f else 0
        best = max(best, run)
    return best


def hiders(grey: np.ndarray, half_width: float) -> np.ndarray:
    """``grey`` (needle-coloured pixels of a window) without the blobs too small to hide a
    wire ``half_width`` px wide (MIN_HIDER_SQUARES) that do not reach the window's edge."""
    return without_small_blobs(grey, MIN_HIDER_SQUARES * (2.0 * half_width) ** 2, True)


def classify_points(
    images: tuple[np.ndarray, np.ndarray],
    views: tuple[MaskView, MaskView],
    stereo: StereoCameraModel,
    world: np.ndarray,
    in_tissue: np.ndarray,
    half_width: float,
    rule: ColourRule,
    tissue_hides: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Each eye's class (SEEN, HIDDEN, EXPOSED) of centre-line points (N, 3, world);
    ``in_tissue`` (N,) marks those the known tissue may hide."""
    classes = []
    for img, view, cam in zip(images, views, (stereo.left, stereo.right), strict=True):
        uv = cam.project(world)
        H, W = img.shape[:2]
        cls = np.full(len(uv), EXPOSED, int)
        u, v = uv[:, 0], uv[:, 1]
        border = (
            ~np.isfinite(u)
            | (u < BORDER_PX)
            | (v < BORDER_PX)
            | (u > W - 1 - BORDER_PX)
            | (v > H - 1 - BORDER_PX)
        )
        inside = ~border
        reach_seen = half_width + SEEN_SLACK_PX
        reach_hide = half_width + HIDER_SLACK_PX
        if inside.any():
            m = int(np.ceil(max(reach_seen, reach_hide))) + 2
            a = max(int(np.floor(u[inside].min())) - m, 0)
            b = min(int(np.ceil(u[inside].max())) + m + 1, W)
            c = max(int(np.floor(v[inside].min())) - m, 0)
            d = min(int(np.ceil(v[inside].max())) + m + 1, H)
            mask = np.zeros((d - c, b - a), bool)
            x0, y0 = view.origin
            h, w = view.mask.shape
            ma, mb, mc, md = max(a, x0), min(b, x0 + w), max(c, y0), min(d, y0 + h)
            if ma < mb and mc < md:
                mask[mc - c : md - c, ma - a : mb - a] = view.mask[
                    mc - y0 : md - y0, ma - x0 : mb - x0
                ]
            metal = hiders(needle_coloured(img[c:d, a:b], rule), half_width) & ~mask
            d_mask = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 3)
            d_metal = cv2.distanceTransform((~metal).astype(np.uint8), cv2.DIST_L2, 3)
            iu = np.clip(np.rint(u[inside]).astype(int) - a, 0, b - a - 1)
            iv = np.clip(np.rint(v[inside]).astype(int) - c, 0, d - c - 1)
            sub = np.full(len(iu), EXPOSED, int)
            sub[d_metal[iv, iu] <= reach_hide] = HIDDEN
            sub[in_tissue[inside]] = HIDDEN
            if tissue_hides:
                sub[tissue_coloured(img[c:d, a:b][iv, iu].astype(np.int16), rule)] = HIDDEN
            sub[d_mask[iv, iu] <= reach_seen] = SEEN
            cls[inside] = sub
        cls[border] = HIDDEN
        classes.append(cls)
    return classes[0], classes[1]


def arc_exposure(
    images: tuple[np.ndarray, np.ndarray],
    views: tuple[MaskView, MaskView],
    stereo: StereoCameraModel,
    T_cam_needle: np.ndarray,
    model: NeedleModel,
    half_width: float,
    rule: ColourRule | None = None,
    inside_tissue: Callable[[np.ndarray], np.ndarray] | None = None,
    tissue_hides: bool = False,
) -> ArcExposure:
    """Class every centre-line sample of the pose (left-camera frame) in both eyes;
    ``tissue_hides``: any tissue-coloured pixel may hide the needle (its depth unknown)."""
    rule = rule or ColourRule()
    angles = np.linspace(model.tip_angle, model.base_angle, N_SAMPLES)
    pts = model.point_at(angles)
    T_world = stereo.left.T_world_cam @ np.asarray(T_cam_needle, float)
    world = pts @ T_world[:3, :3].T + T_world[:3, 3]
    in_tissue = (
        np.zeros(len(pts), bool) if inside_tissue is None else np.asarray(inside_tissue(world))
    )
    deep = (
        np.zeros(len(pts), bool)
        if inside_tissue is None
        else np.asarray(inside_tissue(world, margin=DEEP))
    )
    step = model.radius * (angles[1] - angles[0])
    classes = classify_points(
        images, views, stereo, world, in_tissue, half_width, rule, tissue_hides
    )
    runs, ends, totals, seen = [], [], [], []
    for cls in classes:
        runs.append(_longest_run(cls == EXPOSED) * step)
        ex = cls == EXPOSED
        totals.append(float(ex.sum() * step))
        seen.append(float((cls == SEEN).sum() * step))
        ends.append(max(_leading(ex), _leading(ex[::-1])) * step)
    seen_deep = (classes[0] == SEEN) & (classes[1] == SEEN) & deep
    return ArcExposure(
        (classes[0], classes[1]),
        (runs[0], runs[1]),
        (ends[0], ends[1]),
        float(seen_deep.sum() * step),
        (totals[0], totals[1]),
        (seen[0], seen[1]),
    )


def _leading(flags: np.ndarray) -> int:
    """Length of the run of True at the start."""
    n = np.argmin(flags) if not flags.all() else len(flags)
    return int(n)


def ports_inside(pairs) -> Callable[[np.ndarray], np.ndarray]:
    """``inside_tissue`` from known port pairs ((entry, exit) of (position, outward normal),
    world): inside the ridge under a pair = below both its flanks' surface planes, within
    ``PAIR_REACH`` of the pair's midpoint."""
    tests = [below_port_planes(list(pair)) for pair in pairs]
    mids = [0.5 * (np.asarray(a[0], float) + np.asarray(b[0], float)) for a, b in pairs]

    def inside(world: np.ndarray, margin: float = 0.0) -> np.ndarray:
        w = np.asarray(world, float)
        out = np.zeros(len(w), bool)
        for t, m in zip(tests, mids, strict=True):
            out |= t(w, margin) & (np.linalg.norm(w - m, axis=1) <= PAIR_REACH)
        return out

    return inside


#: Reach (m) around a port pair's midpoint within which its flanks' planes bound the tissue.
PAIR_REACH = 0.015


def tissue_model(
    T_world_phantom: np.ndarray,
    port_pairs,
    eye: np.ndarray,
    footprint: tuple[tuple[float, float], tuple[float, float]] | None = None,
    top_z: float = TISSUE_TOP_Z,
) -> Callable[..., np.ndarray]:
    """``inside_tissue`` from the task's known phantom, seen from a camera at ``eye`` (world):
    a point may be hidden by the tissue when the line of sight to it runs through the solid
    (within ``SIGHT_REACH`` of the point): the tissue block under its top plane within its
    ``footprint`` ((x0, x1), (y0, y1) in the phantom frame; None: unbounded) or the ridge
    under a port pair (:func:`ports_inside`). With ``margin`` > 0 (keyword): whether the point
    itself lies that deep inside the solid."""
    T = np.asarray(T_world_phantom, float)
    ridge = ports_inside(port_pairs) if port_pairs else None
    eye = np.asarray(eye, float)

    def solid(w: np.ndarray, margin: float) -> np.ndarray:
        q = (w - T[:3, 3]) @ T[:3, :3]
        out = q[:, 2] < top_z - margin
        if footprint is not None:
            (x0, x1), (y0, y1) = footprint
            x, y = q[:, 0], q[:, 1]
            out &= (x0 + margin <= x) & (x <= x1 - margin) & (y0 + margin <= y) & (y <= y1 - margin)
        return out | ridge(w, margin) if ridge is not None else out

    def inside(world: np.ndarray, margin: float = 0.0) -> np.ndarray:
        w = np.asarray(world, float).reshape(-1, 3)
        if margin > 0:
            return solid(w, margin)
        d = eye[None] - w
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        steps = np.linspace(0.0, SIGHT_REACH, SIGHT_STEPS)
        ray = w[:, None, :] + steps[None, :, None] * d[:, None, :]
        return solid(ray.reshape(-1, 3), 0.0).reshape(len(w), -1).any(1)

    return inside


@dataclass(frozen=True)
class PhantomTissue:
    """The task's known phantom as a localiser's tissue knowledge: called (world points, and
    ``margin`` as :func:`tissue_model`) it says where the tissue may hide a needle seen from
    its eye; ``pieces`` is its solid as convex pieces of world planes, inside which the fit
    takes the arc as hidden (:func:`~suture_bt.geometry.tissue_surface.solid_pieces`)."""

    inside: Callable[..., np.ndarray]
    pieces: list

    def __call__(self, world: np.ndarray, margin: float = 0.0) -> np.ndarray:
        return self.inside(world, margin=margin)


def phantom_tissue(phantom, eye: np.ndarray) -> PhantomTissue:
    """:func:`tissue_model` of the task's known phantom (a
    :class:`~suture_bt.geometry.PhantomModel`: its pose, port pairs and block) seen from
    ``eye`` (world), with the phantom's solid: the localiser's ``tissue``."""
    pairs = [
        tuple((p.position, p.normal) for p in phantom.pair(k))
        for k in range(1, phantom.num_pairs + 1)
    ]
    inside = tissue_model(phantom.T_world_phantom, pairs, eye, (TISSUE_X, TISSUE_Y))
    return PhantomTissue(inside, solid_pieces(phantom))


#: How far back along the line of sight (m) and in how many steps the tissue is looked for.
SIGHT_REACH = 0.04
SIGHT_STEPS = 41


def below_port_planes(ports: list[tuple[np.ndarray, np.ndarray]]):
    """``inside_tissue`` for a needle known to be in these ports ((position, outward normal)
    world pairs): a point lies inside when it is below every port's surface plane (the ridge
    between an entry and its exit is the solid under both flanks) by more than ``margin``."""
    P = np.array([p for p, _ in ports], float).reshape(-1, 3)
    N = np.array([n for _, n in ports], float).reshape(-1, 3)

    def inside(world: np.ndarray, margin: float = 0.0) -> np.ndarray:
        h = np.einsum("kpj,pj->kp", np.asarray(world, float)[:, None, :] - P[None], N)
        return np.all(h < -margin, axis=1)

    return inside
