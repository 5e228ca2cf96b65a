"""PSM forward kinematics in modified DH (Craig): T_i = Rx(α)·Tx(a)·Rz(θ)·Tz(d).

Frame 0 is the PSM base at the remote centre of motion (RCM); frame 7 is the tool tip
(control point between the jaws). Table and lengths: DESIGN.md §5 (SRC 2021-22, in metres).
"""

from __future__ import annotations

import numpy as np

L_RCC = 0.4389
L_TOOL = 0.416
L_PITCH2YAW = 0.009
L_YAW2CTRLPNT = 0.0106
#: Insertion at which the wrist-pitch axis reaches the RCM.
L_TOOL2RCM = L_RCC - L_TOOL

NUM_JOINTS = 6
JOINT_NAMES = ("outer_yaw", "outer_pitch", "insertion", "tool_roll", "wrist_pitch", "wrist_yaw")
JOINT_IS_PRISMATIC = np.array([False, False, True, False, False, False])

#: (lower, upper) per joint, SI units.
JOINT_LIMITS = np.array(
    [
        [-np.deg2rad(91.96), np.deg2rad(91.96)],
        [-np.deg2rad(60.0), np.deg2rad(60.0)],
        [0.0, 0.24],
        [-np.deg2rad(175.0), np.deg2rad(175.0)],
        [-np.deg2rad(90.0), np.deg2rad(90.0)],
        [-np.deg2rad(85.0), np.deg2rad(85.0)],
    ]
)
JAW_LIMITS = (0.0, 1.57)
#: Jaw angles at or below this count as closing (DESIGN.md §5).
JAW_CLOSED_THRESHOLD = 0.2
#: How far behind the tip control point a held wire sits between the blades (m, along
#: −tip z): the needle driver's pinch point, a fact of the tool like the lengths above.
GRASP_DEPTH = 0.0015


def _dh_rows(q: np.ndarray) -> list[tuple[float, float, float, float]]:
    """(α, a, θ, d) for frames 1..7 at joint vector q."""
    h = np.pi / 2
    return [
        (h, 0.0, q[0] + h, 0.0),
        (-h, 0.0, q[1] - h, 0.0),
        (h, 0.0, 0.0, q[2] - L_RCC),
        (0.0, 0.0, q[3], L_TOOL),
        (-h, 0.0, q[4] - h, 0.0),
        (-h, L_PITCH2YAW, q[5] - h, 0.0),
        (-h, 0.0, h, L_YAW2CTRLPNT),
    ]


def dh_transform(alpha: float, a: float, theta: float, d: float) -> np.ndarray:
    """One modified-DH link transform Rx(α)·Tx(a)·Rz(θ)·Tz(d)."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    ct, st = np.cos(theta), np.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def frame_transforms(q, upto: int = 7) -> list[np.ndarray]:
    """Base-frame transforms of frames 1..upto (frame 7 is the tip) for joints q (6 values)."""
    q = np.asarray(q, dtype=float)
    if q.shape[0] < NUM_JOINTS:
        q = np.concatenate([q, np.zeros(NUM_JOINTS - q.shape[0])])
    T = np.eye(4)
    frames = []
    for row in _dh_rows(q)[:upto]:
        T = T @ dh_transform(*row)
        frames.append(T)
    return frames


def forward_kinematics(q) -> np.ndarray:
    """Tip pose (4×4) in the PSM base (RCM) frame."""
    return frame_transforms(q)[-1]


def limit_violations(q, tol: float = 1e-9) -> list[str]:
    """Human-readable list of joints outside their limits (empty when q is inside)."""
    out = []
    for i, (v, (lo, hi)) in enumerate(zip(q, JOINT_LIMITS, strict=False)):
        if v < lo - tol or v > hi + tol:
            unit = "m" if JOINT_IS_PRISMATIC[i] else "rad"
            out.append(
                f"joint {i + 1} ({JOINT_NAMES[i]}) = {v:.4f} {unit} outside [{lo:.4f}, {hi:.4f}]"
            )
    return out


def clip_to_limits(q) -> np.ndarray:
    """q clipped into the joint limits."""
    return np.clip(np.asarray(q, dtype=float), JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
