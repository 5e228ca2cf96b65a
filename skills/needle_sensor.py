"""The needle sensor skills use: capture a stereo frame and localise the needle in it.

Vision only (images + the calibrated camera model): the localiser's refusal (its reason) and a
lost frame become :class:`NeedleNotSeen`. The last frame and estimate are kept for logging.
"""

from __future__ import annotations

import numpy as np

from suture_bt.interfaces import StereoCameraInterface
from suture_bt.perception.arc_evidence import arc_support
from suture_bt.perception.needle_localizer import NeedleLocalizer
from suture_bt.perception.pose_fit import NeedleNotFound
from suture_bt.skills.context import NeedleNotSeen, NeedleObservation

#: Worst edge residual (px) accepted when the caller checks the answer against a prior (the
#: pose its arm predicts): a needle in a port is partly hidden by the tissue and fits worse,
#: and the prior, not the residual, then guards against a wrong answer.
PRIOR_CHECKED_RMS_PX = 0.9


class VisionNeedleSensor:
    """``observe(previous)``: capture, localise, answer in the world frame or refuse.

    ``prior_checked=True`` says the caller will reject an answer that disagrees with
    ``previous``; the localiser may then accept a looser outline fit.
    """

    def __init__(self, camera: StereoCameraInterface, localizer: NeedleLocalizer | None = None):
        self.camera = camera
        self.localizer = localizer or NeedleLocalizer(camera.model)
        self.last_frame = None
        self.last_estimate = None
        self.calls = 0

    def observe(
        self, previous: np.ndarray | None = None, prior_checked: bool = False
    ) -> NeedleObservation:
        self.calls += 1
        try:
            frame = self.camera.capture()
        except Exception as exc:  # noqa: BLE001 - a lost frame is a refusal with its reason
            raise NeedleNotSeen(f"no frame: {exc}") from exc
        self.last_frame, self.last_estimate = frame, None
        T_cam_world = self.camera.model.left.T_cam_world
        prev_cam = None if previous is None else T_cam_world @ np.asarray(previous, dtype=float)
        strict_rms = self.localizer.max_rms_px
        if prior_checked and prev_cam is not None:
            self.localizer.max_rms_px = max(strict_rms, PRIOR_CHECKED_RMS_PX)
        try:
            est = self.localizer.localize(frame.left, frame.right, previous=prev_cam)
        except NeedleNotFound as exc:
            raise NeedleNotSeen(str(exc)) from exc
        finally:
            self.localizer.max_rms_px = strict_rms
        self.last_estimate = est
        return NeedleObservation(
            est.T_world_needle.copy(),
            frame.stamp,
            float(est.angle_std_deg),
            float(est.position_std_mm),
            "vision",
            {"rms_px": float(est.rms_px), "total_ms": float(est.timings_ms["total"])},
        )

    def support(self, T_world_needle: np.ndarray, angles: np.ndarray) -> tuple[float, float]:
        """Share of the arc at ``angles`` of a predicted pose seen as metal in the last frame."""
        if self.last_frame is None:
            raise NeedleNotSeen("no frame captured yet")
        f = self.last_frame
        return arc_support(
            (f.left, f.right), self.camera.model, T_world_needle, self.localizer.model, angles
        )
