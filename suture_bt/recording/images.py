"""Camera images in rerun, only those perception or calibration captured anyway: JPEG at
``scale`` of full size, with the needle mask outline, the network's keypoints and the fitted
arc over the stereo pair, and the jaw keypoints over the calibration image.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import rerun as rr

from suture_bt.recording.scene import ESTIMATE, needle_points

#: Logged image size relative to the camera's (1920×1080 is logged at 960×540).
IMAGE_SCALE = 0.5
JPEG_QUALITY = 80
EYES = ("left", "right")


def jpeg(rgb: np.ndarray, scale: float = IMAGE_SCALE) -> tuple[rr.EncodedImage, float]:
    """An RGB image downscaled by ``scale`` as a JPEG, and the exact scale used."""
    h, w = rgb.shape[:2]
    size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
    small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA) if scale != 1.0 else rgb
    ok, buf = cv2.imencode(".jpg", small[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return rr.EncodedImage(contents=buf.tobytes(), media_type="image/jpeg"), size[0] / w


def mask_outline(view: Any, scale: float) -> list[np.ndarray]:
    """Outlines (px at ``scale``) of a mask crop: ``view.mask`` at ``view.origin``."""
    mask = np.asarray(getattr(view, "mask", np.zeros((0, 0))), dtype=np.uint8)
    if mask.size == 0 or not mask.any():
        return []
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    x0, y0 = getattr(view, "origin", (0, 0))
    out = []
    for c in contours:
        pts = c.reshape(-1, 2).astype(float) + (x0, y0)
        out.append(np.vstack([pts, pts[:1]]) * scale)
    return out


def log_stereo(
    rec: rr.RecordingStream, frame: Any, estimate: Any, camera_model: Any, needle: Any
) -> None:
    """The stereo pair perception used; with ``estimate``, its masks, keypoints and arc."""
    for i, eye in enumerate(EYES):
        base = f"world/camera/{eye}/image"
        image, s = jpeg(getattr(frame, eye))
        rec.log(base, image)
        if estimate is None:  # refused: the images only, the old overlays cleared
            rec.log(base + "/overlay", rr.Clear(recursive=True))
            continue
        # Masks and keypoints are in the px the localiser measured in (halved for a near
        # needle: ``pixel_scale`` 2).
        px = getattr(estimate, "pixel_scale", 1.0)
        outline = mask_outline(estimate.masks[i], s * px)
        if outline:
            rec.log(base + "/overlay/mask", rr.LineStrips2D(outline, colors=[(255, 60, 200)]))
        else:
            rec.log(base + "/overlay/mask", rr.Clear(recursive=False))
        cam = getattr(camera_model, eye)
        arc = cam.project(needle_points(needle, estimate.T_world_needle)) * s
        rec.log(base + "/overlay/fit", rr.LineStrips2D([arc], colors=[ESTIMATE], labels=["fit"]))
        if eye == "left":
            kp = (np.asarray(estimate.keypoints_left, dtype=float) + 0.5) * px * s - 0.5
            rec.log(
                base + "/overlay/keypoints",
                rr.Points2D(kp, labels=["base", "tip"], colors=[(255, 255, 0)], radii=[3.0]),
            )


def log_calibration(
    rec: rr.RecordingStream,
    arm: str,
    rgb: np.ndarray,
    keypoints: dict[str, np.ndarray],
) -> None:
    """The calibration image of ``arm`` with keypoint sets (name -> 4×2 full-size px)."""
    base = f"camera/calibration/{arm}"
    image, s = jpeg(rgb)
    rec.log(base, image)
    colours = {"from measured joints": (255, 80, 80), "with Δq̂": (80, 255, 80)}
    for name, px in keypoints.items():
        pts = (np.asarray(px, dtype=float).reshape(-1, 2) + 0.5) * s - 0.5
        rec.log(
            f"{base}/keypoints/{name.replace(' ', '_').replace('Δq̂', 'dq')}",
            rr.Points2D(
                pts,
                colors=[colours.get(name, (255, 255, 0))],
                radii=[3.0],
                labels=[f"{name} {k + 1}" for k in range(len(pts))],
            ),
        )
