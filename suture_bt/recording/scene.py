"""The 3D scene in rerun: ports with their 5 mm squares and frames, arms as link chains, the
needle as an arc, camera frusta. World frame, metres, z up.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from suture_bt.geometry.phantom import PORT_MARK_SIZE
from suture_bt.kinematics.psm import frame_transforms

#: Colours (RGB) of what the recording draws.
ESTIMATE, PREDICTED, TRUTH, PLAN = (40, 200, 255), (120, 120, 255), (255, 170, 0), (80, 220, 80)
ARM = {"psm1": (230, 80, 80), "psm2": (80, 160, 230)}
#: Centre-line samples of a drawn needle.
NEEDLE_SAMPLES = 32


def quat_xyzw(R: np.ndarray) -> list[float]:
    """A rotation matrix as an (x, y, z, w) quaternion."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat().tolist()


def log_frame(rec: rr.RecordingStream, path: str, T: np.ndarray, axes: float, **kw: Any) -> None:
    """A pose as a transform with drawn axes ``axes`` metres long."""
    rec.log(
        path,
        rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]),
        rr.TransformAxes3D(axes),
        **kw,
    )


def log_static_scene(rec: rr.RecordingStream, phantom: Any, camera_model: Any) -> None:
    """The ports (frame + 5 mm square each) and the endoscope's eyes, once."""
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    half = PORT_MARK_SIZE / 2
    for port in phantom.ports():
        path = f"world/phantom/ports/{port.name}"
        log_frame(rec, path, port.T, 0.004, static=True)
        rec.log(
            f"{path}/square",
            rr.Boxes3D(half_sizes=[[half, half, 1e-5]], labels=[port.name], colors=[(60, 60, 60)]),
            static=True,
        )
    for eye in ("left", "right"):
        cam = getattr(camera_model, eye)
        log_frame(rec, f"world/camera/{eye}", cam.T_world_cam, 0.005, static=True)


def log_pinholes(rec: rr.RecordingStream, camera_model: Any, scale: float) -> None:
    """Both eyes' pinholes at the logged image size (OpenCV camera frames)."""
    for eye in ("left", "right"):
        cam = getattr(camera_model, eye)
        w, h = int(round(cam.width * scale)), int(round(cam.height * scale))
        small = cam.scaled(w, h)
        rec.log(
            f"world/camera/{eye}/image",
            rr.Pinhole(image_from_camera=small.K, resolution=[w, h], image_plane_distance=0.02),
            static=True,
        )


def arm_points(T_world_base: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The arm's chain: back of the shaft, the RCM, wrist, wrist yaw, tip (world, N×3)."""
    frames = frame_transforms(np.asarray(q, dtype=float))
    local = [frames[2][:3, 3], np.zeros(3), frames[3][:3, 3], frames[5][:3, 3], frames[6][:3, 3]]
    pts = np.asarray(local)
    return pts @ T_world_base[:3, :3].T + T_world_base[:3, 3]


def log_arm(rec: rr.RecordingStream, path: str, T_world_base: np.ndarray, q: Any) -> None:
    """One arm as a line chain with its tip frame (styles: :func:`log_styles`)."""
    q = np.asarray(q, dtype=float)
    rec.log(f"{path}/links", rr.LineStrips3D([arm_points(T_world_base, q)]))
    T_tip = T_world_base @ frame_transforms(q)[-1]
    rec.log(f"{path}/tip", rr.Transform3D(translation=T_tip[:3, 3], mat3x3=T_tip[:3, :3]))


def log_styles(rec: rr.RecordingStream, arms: list[str], needle: Any) -> None:
    """Colours, radii and tip axes, once (per-tick logs then carry positions only)."""
    for prefix, truth in (("world", False), ("ground_truth/world", True)):
        for arm in arms:
            colour = TRUTH if truth else ARM.get(arm, (200, 200, 200))
            rec.log(
                f"{prefix}/{arm}/links",
                rr.LineStrips3D.from_fields(colors=[colour], radii=[0.0006]),
                static=True,
            )
            rec.log(f"{prefix}/{arm}/tip", rr.TransformAxes3D(0.004), static=True)
    for path, colour in (
        ("world/needle/estimate", ESTIMATE),
        ("world/needle/predicted", PREDICTED),
        ("ground_truth/world/needle", TRUTH),
    ):
        rec.log(
            path,
            rr.LineStrips3D.from_fields(colors=[colour], radii=[needle.wire_radius]),
            static=True,
        )


def needle_points(needle: Any, T_world_needle: np.ndarray) -> np.ndarray:
    """The needle's centre-line in the world (N×3)."""
    T = np.asarray(T_world_needle, dtype=float)
    return needle.centerline(NEEDLE_SAMPLES) @ T[:3, :3].T + T[:3, 3]


def log_needle(rec: rr.RecordingStream, path: str, needle: Any, T: np.ndarray) -> None:
    """A needle pose as its arc, base to tip (styles: :func:`log_styles`)."""
    rec.log(path, rr.LineStrips3D([needle_points(needle, T)]))


def log_plan_arc(rec: rr.RecordingStream, path: str, needle: Any, T_entry: np.ndarray) -> None:
    """A planned insertion: the needle at the entry and the circle its tip follows."""
    T = np.asarray(T_entry, dtype=float)
    a = np.linspace(0.0, 2.0 * np.pi, 97)
    circle = needle.point_at(a) @ T[:3, :3].T + T[:3, 3]
    rec.log(
        path,
        rr.LineStrips3D(
            [circle, needle_points(needle, T)],
            colors=[PLAN, (30, 140, 30)],
            radii=[0.00015, needle.wire_radius],
            labels=["tip path", "needle at entry"],
        ),
    )


def log_poses(rec: rr.RecordingStream, path: str, poses: list, colour) -> None:
    """Planned gripper poses as points (positions) with labels 1..n."""
    pts = np.asarray([np.asarray(T, dtype=float)[:3, 3] for T in poses])
    labels = [str(i + 1) for i in range(len(pts))]
    rec.log(path, rr.Points3D(pts, colors=[colour], radii=[0.0012], labels=labels))
