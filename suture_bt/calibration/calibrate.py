"""``calibrate(arm, camera)``: estimate an arm's hidden joint offset from one image, stepwise.

A :class:`Calibration` is ticked by its caller (a skill): ``start()`` checks the setup and
commands the arm to its calibration pose with the jaw open; each ``step(dt)`` advances it
through ``moving`` → ``settling`` → ``done`` (or ``failed``) without blocking. At ``done`` it has
captured one left-eye image, found the 4 jaw keypoints (keypoint CNN on a window around where
the measured joints put the wrist), predicted Δq̂ with the MLP regressor and refined it to the
arm pose the keypoints show (:mod:`reprojection_refine`; ``mlp_raw``: the MLP alone; or the PnP
baseline), checked the result, and installed Δq̂ in the servo's offset compensator when one was
given.

Failure is a :class:`CalibrationFailed` with a ``reason`` (also kept on the object):
``setup`` (the arm base or camera differs from the geometry the regressor was trained for, or
the calibration pose is not in view), ``timeout`` (the arm did not reach the pose),
``keypoints_not_visible`` (low keypoint confidence, or detections inconsistent with any arm
pose: jaw out of view or occluded), ``implausible`` (Δq̂ outside the offset bounds).

Everything planned and measured is kept on the object (phase, target, image time stamp,
keypoints, confidences, residual, Δq̂) for inspection and logging.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from suture_bt.calibration.calibration_pose import (
    CALIBRATION_JAW,
    CALIBRATION_POSES,
    OFFSET_BOUND,
    offset_box_points,
)
from suture_bt.calibration.geometric_baseline import pnp_offset
from suture_bt.calibration.jaw_keypoints import project_keypoints
from suture_bt.calibration.keypoint_net import KEYPOINT_SIGMA_PX
from suture_bt.calibration.reprojection_refine import refine_offset
from suture_bt.calibration.scene_geometry import PSM_BASES, REFERENCE_SIZE, eye_pose

#: Δq̂ beyond the bounds by more than this factor is implausible.
PLAUSIBLE_FACTOR = 1.2
#: Keypoint residual (RMS over keypoints of error / KEYPOINT_SIGMA_PX) above which detections
#: do not fit the arm model. In view: ≤ 9.1 in the benchmark's 204 frames (one above 8);
#: jaw out of view: ~1000.
MAX_RESIDUAL_SIGMA = 12.0
#: Fine-stage peak mass below which a keypoint counts as not found.
MIN_KEYPOINT_CONFIDENCE = 0.3
#: confidence = min keypoint confidence · exp(−½ (r / RESIDUAL_SCALE)²), r the normalised residual.
RESIDUAL_SCALE = 2.0


class CalibrationFailed(RuntimeError):
    """Calibration could not produce a trustworthy offset; ``reason`` is a short code."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass
class CalibrationResult:
    """What one calibration measured and concluded (SI units)."""

    arm: str
    offset: np.ndarray  # Δq̂ (3): rad, rad, m
    confidence: float  # 0..1
    keypoints: np.ndarray  # 4×2 image px (left eye)
    keypoint_confidence: np.ndarray  # 4
    residual_px: float  # RMS keypoint residual of the estimate, px at 1920×1080
    q_meas: np.ndarray  # measured joints at capture
    stamp: float  # capture time (simulated s)
    method: str
    compute_ms: float  # detection + regression time (wall clock)
    extra: dict = field(default_factory=dict)


_MODELS: dict = {}


def _shipped(kind: str):
    """The shipped keypoint detector or offset regressor, loaded once."""
    if kind not in _MODELS:
        from suture_bt.calibration.keypoint_net import KeypointDetector
        from suture_bt.calibration.offset_regressor import OffsetRegressor

        loader = KeypointDetector if kind == "detector" else OffsetRegressor
        _MODELS[kind] = loader.load()
    return _MODELS[kind]


def estimate_offset(
    arm: str,
    image: np.ndarray,
    cam,
    q_meas,
    *,
    method: str = "mlp",
    detector=None,
    regressor=None,
    stamp: float = 0.0,
) -> CalibrationResult:
    """Δq̂ from one left-eye image taken at the calibration pose; raises CalibrationFailed."""
    t0 = time.perf_counter()
    detector = detector or _shipped("detector")
    if method in ("mlp", "mlp_raw"):
        regressor = regressor or _shipped("regressor")
    q_meas = np.asarray(q_meas, dtype=float)
    T_base = PSM_BASES[arm]
    expected = project_keypoints(q_meas, CALIBRATION_JAW, T_base, cam)[0]
    kp, conf, _ = detector.detect(image, cam, expected.mean(0))
    if method in ("mlp", "mlp_raw"):
        offset = regressor.predict(arm, kp[None], cam.width, cam.height, q_meas[None])[0]
        if method == "mlp":  # refined to the pose the detections show (reprojection_refine)
            sigma = np.asarray(KEYPOINT_SIGMA_PX) * cam.height / REFERENCE_SIZE[1]
            offset = refine_offset(offset, kp, q_meas, CALIBRATION_JAW, T_base, cam, sigma)
    elif method == "pnp":
        offset = pnp_offset(kp, q_meas, CALIBRATION_JAW, T_base, cam)
    else:
        raise ValueError(f"method must be 'mlp', 'mlp_raw' or 'pnp', got {method!r}")
    q_est = q_meas.copy()
    q_est[:3] += offset
    reproj = project_keypoints(q_est, CALIBRATION_JAW, T_base, cam)[0]
    to_ref = REFERENCE_SIZE[1] / cam.height
    dist = np.linalg.norm(reproj - kp, axis=1) * to_ref
    residual = float(np.sqrt(np.mean(dist**2)))
    normalised = float(np.sqrt(np.mean((dist / np.asarray(KEYPOINT_SIGMA_PX)) ** 2)))
    confidence = float(np.min(conf) * np.exp(-0.5 * (normalised / RESIDUAL_SCALE) ** 2))
    result = CalibrationResult(
        arm=arm,
        offset=offset,
        confidence=confidence,
        keypoints=kp,
        keypoint_confidence=conf,
        residual_px=residual,
        q_meas=q_meas,
        stamp=stamp,
        method=method,
        compute_ms=(time.perf_counter() - t0) * 1e3,
        extra={"residual_sigma": normalised},
    )
    check_result(result)
    return result


def check_result(r: CalibrationResult) -> None:
    """Raise CalibrationFailed when keypoints were not found or Δq̂ is implausible."""
    if np.min(r.keypoint_confidence) < MIN_KEYPOINT_CONFIDENCE:
        worst = int(np.argmin(r.keypoint_confidence))
        raise CalibrationFailed(
            "keypoints_not_visible",
            f"keypoint {worst} confidence {r.keypoint_confidence[worst]:.2f} "
            f"< {MIN_KEYPOINT_CONFIDENCE} (jaw out of view or occluded?)",
        )
    normalised = r.extra.get("residual_sigma", 0.0)
    if normalised > MAX_RESIDUAL_SIGMA:
        raise CalibrationFailed(
            "keypoints_not_visible",
            f"detected keypoints fit no arm pose (residual {r.residual_px:.1f} px, "
            f"{normalised:.1f} σ > {MAX_RESIDUAL_SIGMA} σ): jaw out of view, occluded or another "
            "object",
        )
    excess = np.abs(r.offset) / OFFSET_BOUND
    if np.any(excess > PLAUSIBLE_FACTOR):
        raise CalibrationFailed(
            "implausible",
            f"estimated offset {np.round(r.offset, 5).tolist()} exceeds the bounds "
            f"(±5°, ±5°, ±5 mm) by more than {PLAUSIBLE_FACTOR}×",
        )


def check_setup(arm_name: str, T_world_base: np.ndarray, cam) -> None:
    """Raise CalibrationFailed("setup") if the geometry differs from the trained one."""
    T_ref = PSM_BASES[arm_name]
    if np.abs(T_world_base - T_ref).max() > 1e-3:
        raise CalibrationFailed(
            "setup", f"{arm_name} base frame differs from the SRC scene the regressor knows"
        )
    if np.abs(cam.T_world_cam - eye_pose("left")).max() > 1e-3:
        raise CalibrationFailed("setup", "left camera pose differs from the SRC endoscope")
    grid = np.tile(CALIBRATION_POSES[arm_name], (27, 1))
    grid[:, :3] += offset_box_points(3)
    px = project_keypoints(grid, CALIBRATION_JAW, T_ref, cam)
    if px.min() < 0 or px[..., 0].max() > cam.width - 1 or px[..., 1].max() > cam.height - 1:
        raise CalibrationFailed("setup", "the calibration pose is not fully in the left image")


class Calibration:
    """Stepwise calibration of one arm (see the module docstring).

    ``servo`` is optional: a PI servo with ``servo_jp(true q)``, ``offset_estimate`` and
    ``set_offset_estimate``; when given, the pose is commanded through it and Δq̂ is installed
    in it. Without it the arm is commanded with ``move_jp`` and the result is only reported.
    """

    def __init__(
        self,
        arm,
        camera,
        servo=None,
        *,
        method: str = "mlp",
        settle_time: float = 0.4,
        timeout: float = 10.0,
        speed: float = 0.5,
        detector=None,
        regressor=None,
    ):
        self.arm = arm
        self.name = getattr(arm, "name", None)
        if self.name not in CALIBRATION_POSES:
            raise ValueError(
                f"arm name must be one of {sorted(CALIBRATION_POSES)}, got {self.name}"
            )
        self.camera = camera
        self.servo = servo
        self.method = method
        self.settle_time = settle_time
        self.timeout = timeout
        self.speed = speed  # rad/s (and 0.1 m/s scaled) for the servo-driven approach
        self.detector, self.regressor = detector, regressor
        self.phase = "idle"
        self.elapsed = 0.0
        self.target = CALIBRATION_POSES[self.name].copy()
        self.result: CalibrationResult | None = None
        self.failure: CalibrationFailed | None = None
        self._start_q: np.ndarray | None = None
        self._settled_for = 0.0
        self._prior = np.zeros(3)

    # ------------------------------------------------------------------ stepping
    def start(self) -> None:
        """Check the setup and command the calibration pose (jaw open)."""
        self.elapsed = 0.0
        self.result, self.failure = None, None
        try:
            check_setup(self.name, self.arm.base_frame(), self.camera.model.left)
        except CalibrationFailed as e:
            self._fail(e)
            return
        self.arm.jaw.move_jp(np.array([CALIBRATION_JAW]))
        if self.servo is not None:
            self._prior = np.asarray(self.servo.offset_estimate, dtype=float)[:3].copy()
            self._start_q = np.asarray(self.arm.measured_jp(), dtype=float)
        else:
            self.arm.move_jp(self.target)
        self.phase = "moving"

    def step(self, dt: float) -> str:
        """Advance by dt seconds of simulated time; returns the phase."""
        if self.phase in ("idle", "done", "failed"):
            return self.phase
        self.elapsed += dt
        if self.elapsed > self.timeout:
            self._fail(CalibrationFailed("timeout", f"pose not reached in {self.timeout} s"))
            return self.phase
        if self.phase == "moving":
            if self._moving_done():
                self.phase = "settling"
                self._settled_for = 0.0
        elif self.phase == "settling":
            self._settled_for += dt
            still = np.all(np.abs(self.arm.measured_jv()) < 1e-3)
            if self._settled_for >= self.settle_time and still and not self.arm.jaw.is_busy():
                self._measure()
        return self.phase

    def _moving_done(self) -> bool:
        if self.servo is None:
            return not self.arm.is_busy()
        # Servo-driven: interpolate the desired (measured-space) joints at a bounded speed.
        dist = np.abs(self.target - self._start_q) / np.array([1, 1, 0.1, 1, 1, 1])
        duration = max(float(dist.max()) / self.speed, 1e-3)
        s = min(self.elapsed / duration, 1.0)
        s = s * s * (3 - 2 * s)
        q_meas_goal = self._start_q + s * (self.target - self._start_q)
        q_true = q_meas_goal.copy()
        q_true[:3] += self._prior
        self.servo.servo_jp(q_true)
        return self.elapsed >= duration

    def _measure(self) -> None:
        frame = self.camera.capture()
        q_meas = np.asarray(self.arm.measured_jp(), dtype=float)
        try:
            self.result = estimate_offset(
                self.name,
                frame.left,
                self.camera.model.left,
                q_meas,
                method=self.method,
                detector=self.detector,
                regressor=self.regressor,
                stamp=frame.stamp,
            )
        except CalibrationFailed as e:
            self._fail(e)
            return
        if self.servo is not None:
            self.servo.set_offset_estimate(self.result.offset)
        self.phase = "done"

    def _fail(self, e: CalibrationFailed) -> None:
        self.failure = e
        self.phase = "failed"

    def raise_if_failed(self) -> None:
        if self.failure is not None:
            raise self.failure


def calibrate(arm, camera, servo=None, **kwargs) -> Calibration:
    """A started :class:`Calibration` of ``arm``; tick it with ``step(dt)`` until done/failed."""
    c = Calibration(arm, camera, servo, **kwargs)
    c.start()
    return c
