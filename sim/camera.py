"""The simulated stereo endoscope (DESIGN.md §5): exact-resolution pinhole renders of both eyes.

Geometry: the camera frame sits at (0, 0.0963, 0.1671) with RPY (0.6981, 0, −π); the eyes sit
±2 mm along its x and 50 mm along its −z and look along its −z with +y up. Each eye is exposed
as a :class:`CameraModel` in the OpenCV convention (x right, y down, z forward; integer pixel
centres; principal point ((W−1)/2, (H−1)/2); f = H / (2·tan 0.6)).

Every image is rendered at exactly the claimed resolution: the EGL plugin upsamples anything
larger than 1024×768, so bigger images are stitched from tiles, each rendered with its own
off-centre frustum that covers exactly its pixels.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as p

from suture_bt.interfaces import CameraModel, FrameLost, StereoCameraModel, StereoFrame
from suture_bt.sim.quiet import quiet_fd
from suture_bt.sim.rendering import MAX_TILE_HEIGHT, MAX_TILE_WIDTH, load_renderer
from suture_bt.transforms import invert, make_transform, pose_to_transform

CAMERA_FRAME_POSITION = (0.0, 0.0963, 0.1671)
CAMERA_FRAME_RPY = (0.6981, 0.0, -np.pi)
#: Half the 4 mm stereo baseline, along the camera frame's x.
EYE_HALF_BASELINE = 0.002
#: Distance of the eyes from the camera frame along its −z.
EYE_SETBACK = 0.05
FOV_Y = 1.2
NEAR = 0.005
FAR = 2.0
#: Rotation from an OpenGL-style eye frame (x right, y up, z backward) to OpenCV (y down, z fwd).
R_GL_CV = np.diag([1.0, -1.0, -1.0])
#: TinyRenderer draws everything about (+0.5, −0.5) px off the pixel-centre convention
#: (measured; DESIGN.md §5); its frustum is shifted by this much to compensate.
TINY_PIXEL_SHIFT = (0.5, -0.5)
#: RGB shown where no object is hit (the dark body cavity rather than pybullet's grey-blue).
BACKGROUND_RGB = (24, 14, 14)
#: Direction towards the light, world frame. Overhead: oblique directions make the EGL
#: renderer's shadow map cut a hard, false edge across the tissue.
LIGHT_DIRECTION_WORLD = (0.0, 0.0, 1.0)


def light_direction(tilt_deg: float, azimuth_deg: float) -> tuple[float, float, float]:
    """Unit direction towards a light tilted ``tilt_deg`` from overhead toward world azimuth
    ``azimuth_deg`` (the lighting fault's and the training data's tilted lights)."""
    t, a = math.radians(tilt_deg), math.radians(azimuth_deg)
    return (math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t))


def default_camera_frame() -> np.ndarray:
    """World pose of the SRC endoscope's camera frame."""
    return pose_to_transform(CAMERA_FRAME_POSITION, CAMERA_FRAME_RPY)


def stereo_model(
    width: int, height: int, T_world_camframe: np.ndarray | None = None
) -> StereoCameraModel:
    """Left/right pinhole models (OpenCV convention) of the endoscope at a resolution."""
    if int(width) != width or int(height) != height or width < 2 or height < 2:
        raise ValueError(f"camera resolution must be integers ≥ 2, got {width}×{height}")
    T_cf = default_camera_frame() if T_world_camframe is None else np.asarray(T_world_camframe)
    if T_cf.shape != (4, 4):
        raise ValueError(f"T_world_camframe must be 4×4, got shape {T_cf.shape}")
    eyes = []
    for side in (-1.0, 1.0):  # left eye at −x (image left), right eye at +x
        T_cf_eye = make_transform(R_GL_CV, (side * EYE_HALF_BASELINE, 0.0, -EYE_SETBACK))
        eyes.append(CameraModel.from_fov(int(width), int(height), FOV_Y, T_cf @ T_cf_eye))
    return StereoCameraModel(left=eyes[0], right=eyes[1])


@dataclass(frozen=True)
class CaptureFault:
    """What a fault does to one capture: lost (no images), or a gain and a light direction."""

    lost: bool = False
    reason: str = ""
    gain: float = 1.0
    light_direction: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class RenderResult:
    """One rendered eye: RGB (H×W×3 uint8), metric depth (H×W, m) and pybullet segmentation.

    ``segmentation`` holds ``body_id + ((link_index + 1) << 24)`` per pixel, −1 for background
    (pybullet's ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX encoding).
    """

    rgb: np.ndarray
    depth: np.ndarray
    segmentation: np.ndarray | None

    @property
    def body_ids(self) -> np.ndarray:
        """Body unique id per pixel (−1 for background)."""
        seg = self._seg()
        return np.where(seg >= 0, seg & ((1 << 24) - 1), -1)

    @property
    def link_ids(self) -> np.ndarray:
        """Link index per pixel (−1 for a base link, −2 for background)."""
        seg = self._seg()
        return np.where(seg >= 0, (seg >> 24) - 1, -2)

    def mask(self, body_id: int, link_index: int | None = None) -> np.ndarray:
        """Boolean mask of a body (or of one of its links)."""
        m = self.body_ids == body_id
        if link_index is not None:
            m &= self.link_ids == link_index
        return m

    def _seg(self) -> np.ndarray:
        if self.segmentation is None:
            raise ValueError("rendered without segmentation")
        return self.segmentation


def _gl_matrix(M: np.ndarray) -> list[float]:
    """A 4×4 matrix as the column-major float list pybullet expects."""
    return [float(v) for v in M.T.ravel()]


def _frustum(left: float, right: float, bottom: float, top: float) -> np.ndarray:
    """OpenGL glFrustum projection matrix."""
    n, f = NEAR, FAR
    return np.array(
        [
            [2 * n / (right - left), 0.0, (right + left) / (right - left), 0.0],
            [0.0, 2 * n / (top - bottom), (top + bottom) / (top - bottom), 0.0],
            [0.0, 0.0, -(f + n) / (f - n), -2 * f * n / (f - n)],
            [0.0, 0.0, -1.0, 0.0],
        ]
    )


def _tiles(size: int, max_tile: int) -> list[tuple[int, int]]:
    """Split [0, size) into near-equal [start, stop) pieces of at most max_tile pixels."""
    n = math.ceil(size / max_tile)
    edges = [round(i * size / n) for i in range(n + 1)]
    return list(zip(edges[:-1], edges[1:], strict=True))


def render_view(
    client: int,
    cam: CameraModel,
    with_segmentation: bool = True,
    light_direction=None,
) -> RenderResult:
    """Render a pinhole camera exactly (tiles above 1024×768).

    With segmentation, pixels that hit nothing are painted ``BACKGROUND_RGB``; without it
    (faster) they keep pybullet's clear colour, which the phantom's floor hides in the scene.
    """
    kind = load_renderer(client)
    flag = p.ER_BULLET_HARDWARE_OPENGL if kind == "egl" else p.ER_TINY_RENDERER
    T_world_gl = cam.T_world_cam @ make_transform(R_GL_CV)
    view = _gl_matrix(invert(T_world_gl))
    if light_direction is None:
        light_direction = LIGHT_DIRECTION_WORLD
    max_w, max_h = (MAX_TILE_WIDTH, MAX_TILE_HEIGHT) if kind == "egl" else (cam.width, cam.height)
    du, dv = (0.0, 0.0) if kind == "egl" else TINY_PIXEL_SHIFT
    W, H = cam.width, cam.height
    rgb = np.empty((H, W, 3), np.uint8)
    zbuf = np.empty((H, W), np.float32)
    seg = np.full((H, W), -1, np.int32)
    # The segmentation pass costs ~40 % extra; captures skip it (the phantom's dark floor
    # fills the background, so no darkening is needed).
    flags = (
        p.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX
        if with_segmentation
        else p.ER_NO_SEGMENTATION_MASK
    )
    for r0, r1 in _tiles(H, max_h):
        for c0, c1 in _tiles(W, max_w):
            # Tile edges (pixel centre ± 0.5) on the near plane; rows run downwards in OpenCV.
            left = NEAR * (c0 - 0.5 + du - cam.cx) / cam.fx
            right = NEAR * (c1 - 0.5 + du - cam.cx) / cam.fx
            top = NEAR * (cam.cy - (r0 - 0.5 + dv)) / cam.fy
            bottom = NEAR * (cam.cy - (r1 - 0.5 + dv)) / cam.fy
            proj = _gl_matrix(_frustum(left, right, bottom, top))
            w, h = c1 - c0, r1 - r0
            with quiet_fd(1):  # the EGL plugin's banner when it first renders
                _, _, img, depth, segm = p.getCameraImage(
                    w,
                    h,
                    viewMatrix=view,
                    projectionMatrix=proj,
                    renderer=flag,
                    flags=flags,
                    lightDirection=[float(v) for v in light_direction],
                    shadow=0,
                    physicsClientId=client,
                )
            rgb[r0:r1, c0:c1] = np.asarray(img, np.uint8).reshape(h, w, 4)[:, :, :3]
            zbuf[r0:r1, c0:c1] = np.asarray(depth, np.float32).reshape(h, w)
            if with_segmentation:
                seg[r0:r1, c0:c1] = np.asarray(segm, np.int32).reshape(h, w)
    if with_segmentation:
        rgb[seg < 0] = BACKGROUND_RGB
    depth_m = FAR * NEAR / (FAR - (FAR - NEAR) * zbuf.astype(np.float64))
    return RenderResult(rgb=rgb, depth=depth_m, segmentation=seg if with_segmentation else None)


class StereoEndoscope:
    """The SRC stereo endoscope; implements ``StereoCameraInterface``.

    ``noise_std`` is the standard deviation of additive Gaussian sensor noise in 8-bit grey
    levels; ``brightness`` scales the image before noise. ``T_world_camframe`` overrides the
    camera-frame pose (eyes keep their offsets in it).
    """

    def __init__(
        self,
        client: int,
        width: int = 1920,
        height: int = 1080,
        noise_std: float = 0.0,
        brightness: float = 1.0,
        rng: np.random.Generator | None = None,
        T_world_camframe: np.ndarray | None = None,
    ) -> None:
        if noise_std < 0 or brightness <= 0:
            raise ValueError(
                f"need noise_std ≥ 0 and brightness > 0, got {noise_std}, {brightness}"
            )
        self.client = client
        self.noise_std = float(noise_std)
        self.brightness = float(brightness)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._model = stereo_model(width, height, T_world_camframe)
        self._clock: Callable[[], float] | None = None
        #: Called with the stamp of every capture (set by :mod:`suture_bt.sim.faults`); returns
        #: a :class:`CaptureFault` or None (no fault).
        self.fault_hook: Callable[[float], CaptureFault | None] | None = None
        self.renderer = load_renderer(client)

    @property
    def model(self) -> StereoCameraModel:
        return self._model

    @property
    def width(self) -> int:
        return self._model.left.width

    @property
    def height(self) -> int:
        return self._model.left.height

    def set_clock(self, fn: Callable[[], float]) -> None:
        """Source of the time stamp put on captures (simulated seconds)."""
        self._clock = fn

    def eye(self, eye: str) -> CameraModel:
        if eye not in ("left", "right"):
            raise ValueError(f"eye must be 'left' or 'right', got {eye!r}")
        return self._model.left if eye == "left" else self._model.right

    def render(self, eye: str, with_segmentation: bool = True) -> RenderResult:
        """Noise-free render of one eye with depth and segmentation (ground truth, data)."""
        return render_view(self.client, self.eye(eye), with_segmentation)

    def capture(self, stamp: float | None = None) -> StereoFrame:
        """Both eyes as a real camera delivers them: brightness and sensor noise applied.

        Raises :class:`~suture_bt.interfaces.FrameLost` when the frame is lost (a fault);
        darkening and lighting faults change the images instead.
        """
        if stamp is None:
            stamp = self._clock() if self._clock is not None else 0.0
        fault = self.fault_hook(float(stamp)) if self.fault_hook is not None else None
        if fault is None:
            left = self._sensor(self.render("left", with_segmentation=False).rgb)
            right = self._sensor(self.render("right", with_segmentation=False).rgb)
            return StereoFrame(left=left, right=right, stamp=float(stamp))
        if fault.lost:
            raise FrameLost(fault.reason or "frame lost", float(stamp))
        light = fault.light_direction
        views = [render_view(self.client, self.eye(e), False, light) for e in ("left", "right")]
        left, right = (self._sensor(v.rgb, fault.gain) for v in views)
        return StereoFrame(left=left, right=right, stamp=float(stamp))

    def _sensor(self, rgb: np.ndarray, gain: float = 1.0) -> np.ndarray:
        if self.brightness * gain == 1.0 and self.noise_std == 0.0:
            return rgb
        img = rgb.astype(np.float32)
        img *= self.brightness * gain
        if self.noise_std > 0:
            noise = self.rng.standard_normal(img.shape, dtype=np.float32)
            noise *= self.noise_std
            img += noise
        np.rint(img, out=img)
        np.clip(img, 0, 255, out=img)
        return img.astype(np.uint8)
