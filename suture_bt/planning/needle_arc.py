"""Needle-arc planning through an entry/exit port pair (seed: drive the needle along its circle).

The needle is a circular arc of radius r (:class:`~suture_bt.geometry.NeedleModel`). For a
port pair, the planner finds the circle of radius r through both ports in the plane that
contains them and the surface normals, choosing the centre and direction whose arc between
the ports runs inside the tissue (enters against the entry normal, leaves along the exit
normal, mid-arc below both port planes). Insertion rotates the needle about its own centre
(needle z = circle axis; the tip moves toward decreasing arc angle, i.e. about −z) from
tip-at-entry until the tip stands ``min_tip_out`` + ``margin`` above the exit's surface plane
(height along the exit normal, the strictest reading of "tip out past the exit"); the
overshoot angle is solved in closed form. Extraction continues the same rotation until the
needle's base end has left the exit, so the other arm can pull it through. Any phantom pose
works: only port frames are used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.geometry import NeedleModel, Port
from suture_bt.planning.timing import make_profile
from suture_bt.transforms import invert

#: SRC throw rule: at least this much tip out past the exit (DESIGN.md §5).
MIN_TIP_OUT = 0.005


class NeedleArcError(ValueError):
    """No valid needle arc for these ports and this needle; ``reason`` says why."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


@dataclass(frozen=True)
class TimedPoses:
    """Poses (N×4×4) with their times (N,) in seconds from the start of the motion."""

    times: np.ndarray
    poses: np.ndarray

    def __len__(self) -> int:
        return len(self.times)

    def transformed(self, T_left: np.ndarray | None = None, T_right: np.ndarray | None = None):
        """Same timing, each pose P replaced by T_left · P · T_right."""
        L = np.eye(4) if T_left is None else np.asarray(T_left, dtype=float)
        R = np.eye(4) if T_right is None else np.asarray(T_right, dtype=float)
        return TimedPoses(self.times.copy(), np.einsum("ij,njk,kl->nil", L, self.poses, R))


@dataclass(frozen=True)
class NeedleArc:
    """A planned needle circle through a port pair; angles are sweep angles φ about −z."""

    entry: Port
    exit: Port
    needle: NeedleModel
    #: Needle pose (world) with the tip exactly at the entry port (φ = 0).
    T_world_needle_entry: np.ndarray
    #: Sweep from tip-at-entry to tip-at-exit.
    port_angle: float
    #: Extra sweep after tip-at-exit until the tip is ``tip_out`` above the exit plane.
    overshoot_angle: float
    tip_out: float
    #: Extra sweep after the base reaches the exit, so the base end is clear of the tissue.
    extraction_clearance_angle: float

    @property
    def center(self) -> np.ndarray:
        return self.T_world_needle_entry[:3, 3].copy()

    @property
    def axis(self) -> np.ndarray:
        """Needle z axis (circle axis) in the world; the tip moves about −axis."""
        return self.T_world_needle_entry[:3, 2].copy()

    @property
    def insert_end_angle(self) -> float:
        return self.port_angle + self.overshoot_angle

    @property
    def base_at_exit_angle(self) -> float:
        """Sweep at which the needle's base end reaches the exit port."""
        return self.port_angle + self.needle.arc_angle

    @property
    def extract_end_angle(self) -> float:
        return self.base_at_exit_angle + self.extraction_clearance_angle

    def needle_pose(self, phi: float) -> np.ndarray:
        """Needle pose (world) after sweeping φ about its own −z from tip-at-entry."""
        return self.T_world_needle_entry @ _rot_z(-phi)

    def sweep_angle_of(self, R_world_needle: np.ndarray) -> tuple[float, float]:
        """The sweep angle whose needle orientation is nearest ``R_world_needle``, and the
        turn (rad) left between them: the sweep turns the needle about its own centre, so the
        orientation alone tells how far along the circle it is (near the insertion end when
        two angles are a full turn apart)."""
        M = self.T_world_needle_entry[:3, :3].T @ np.asarray(R_world_needle, dtype=float)[:3, :3]
        phi = -float(np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1]))
        phi += 2 * np.pi * round((self.insert_end_angle - phi) / (2 * np.pi))
        residual = _rot_z(-phi)[:3, :3].T @ M
        turn = float(np.arccos(np.clip((np.trace(residual) - 1.0) / 2.0, -1.0, 1.0)))
        return phi, turn

    def tip_position(self, phi: float) -> np.ndarray:
        """The tip (world) after sweeping φ."""
        return (self.needle_pose(phi) @ np.r_[self.needle.tip, 1.0])[:3]

    def tip_height_above_exit(self, phi: float) -> float:
        """Signed height of the tip above the exit's surface plane (along its normal)."""
        return float(np.dot(self.tip_position(phi) - self.exit.position, self.exit.normal))

    def grasp_limit_angle(self, T_gripper_needle: np.ndarray, jaw_clearance: float) -> float:
        """Largest sweep before the grasp point comes within ``jaw_clearance`` of the entry."""
        p = invert(np.asarray(T_gripper_needle, dtype=float))[:3, 3]
        theta_g = float(np.arctan2(p[1], p[0])) % (2 * np.pi)
        return theta_g - self.needle.tip_angle - jaw_clearance / self.needle.radius

    def check_grasp(self, T_gripper_needle: np.ndarray, jaw_clearance: float = 0.0015) -> None:
        """Raise :class:`NeedleArcError` if the insertion would drive the jaws into tissue."""
        limit = self.grasp_limit_angle(T_gripper_needle, jaw_clearance)
        if self.insert_end_angle > limit:
            raise NeedleArcError(
                f"the grasp point is too close to the tip: insertion sweeps "
                f"{np.rad2deg(self.insert_end_angle):.1f}° but the jaws reach the entry "
                f"(with {1e3 * jaw_clearance:.1f} mm clearance) after {np.rad2deg(limit):.1f}°"
            )

    def sweep(
        self,
        phi_start: float,
        phi_end: float,
        angular_speed: float = 0.3,
        angular_acc: float = 1.5,
        dt: float = 0.02,
        profile: str = "trapezoidal",
    ) -> TimedPoses:
        """Timed needle poses from φ_start to φ_end under angular speed/acceleration limits."""
        if dt <= 0 or not np.isfinite(dt):
            raise ValueError(f"dt must be positive, got {dt}")
        prof = make_profile(profile, [phi_end - phi_start], [angular_speed], [angular_acc])
        n = max(2, int(np.ceil(prof.duration / dt)) + 1)
        times = np.linspace(0.0, prof.duration, n)
        phis = [phi_start + prof.s(t) * (phi_end - phi_start) for t in times]
        return TimedPoses(times, np.stack([self.needle_pose(p) for p in phis]))

    def approach_poses(self, pre_arc: float = 0.006, lift: float = 0.010) -> list[np.ndarray]:
        """Needle poses to approach the insertion start: lifted along the entry normal, then
        with the tip ``pre_arc`` (arc length) before the entry on the needle's circle.

        Starting the sweep a few millimetres before the entry lets the arm's joints get
        moving (break away from stiction) before the tip reaches the tissue.
        """
        T_pre = self.needle_pose(self.pre_insertion_angle(pre_arc))
        T_lift = T_pre.copy()
        T_lift[:3, 3] += lift * self.entry.normal
        return [T_lift, T_pre]

    def pre_insertion_angle(self, pre_arc: float = 0.006) -> float:
        """Sweep angle (negative) with the tip ``pre_arc`` of arc length before the entry."""
        if pre_arc < 0 or not np.isfinite(pre_arc):
            raise ValueError(f"pre_arc must be a non-negative length, got {pre_arc}")
        return -pre_arc / self.needle.radius

    def insertion(self, start_angle: float = 0.0, **timing) -> TimedPoses:
        """Timed needle poses from φ = ``start_angle`` (0: tip at entry) to the insertion end."""
        return self.sweep(start_angle, self.insert_end_angle, **timing)

    def extraction(self, start_angle: float | None = None, **timing) -> TimedPoses:
        """Timed needle poses continuing from the insertion end (or from ``start_angle``,
        where the needle was left) until the base has left the exit."""
        start = self.insert_end_angle if start_angle is None else float(start_angle)
        return self.sweep(start, self.extract_end_angle, **timing)


def gripper_poses(needle_poses: TimedPoses, T_gripper_needle: np.ndarray) -> TimedPoses:
    """World tip-frame poses of the arm holding the needle with ``T_gripper_needle``."""
    return needle_poses.transformed(T_right=invert(np.asarray(T_gripper_needle, dtype=float)))


def in_base(poses: TimedPoses, T_world_base: np.ndarray) -> TimedPoses:
    """World poses expressed in an arm's base frame (``T_world_base = psm.base_frame()``)."""
    return poses.transformed(T_left=invert(np.asarray(T_world_base, dtype=float)))


def _candidates(entry: Port, exit_: Port, r: float):
    """(arc angle, centre, motion axis) for both circles and both directions that fit."""
    pe, px, ne, nx = entry.position, exit_.position, entry.normal, exit_.normal
    d = px - pe
    c = float(np.linalg.norm(d))
    if c < 1e-6:
        raise NeedleArcError("entry and exit ports coincide")
    if c > 2 * r:
        raise NeedleArcError(
            f"the ports are {1e3 * c:.2f} mm apart, more than the needle's diameter "
            f"{2e3 * r:.2f} mm: no circle of the needle radius passes through both"
        )
    a = np.cross(d, ne + nx)
    if np.linalg.norm(a) < 1e-9 * c:
        a = np.cross(d, ne)
    if np.linalg.norm(a) < 1e-9 * c:
        raise NeedleArcError("the port normals are parallel to the line between the ports")
    a = _unit(a)
    m = np.cross(a, d / c)
    h = np.sqrt(max(r * r - c * c / 4.0, 0.0))
    out = []
    for centre in ((pe + px) / 2 + h * m, (pe + px) / 2 - h * m):
        ue, ux = (pe - centre) / r, (px - centre) / r
        for w in (a, -a):  # motion is a right-handed rotation about w
            angle = float(np.arctan2(np.dot(w, np.cross(ue, ux)), np.dot(ue, ux))) % (2 * np.pi)
            te, tx = np.cross(w, ue), np.cross(w, ux)
            half = np.cos(angle / 2) * ue + np.sin(angle / 2) * np.cross(w, ue)
            mid = centre + r * half
            inside = (
                np.dot(te, ne) < 0
                and np.dot(tx, nx) > 0
                and np.dot(mid - pe, ne) < 0
                and np.dot(mid - px, nx) < 0
            )
            if inside:
                depth = min(-float(np.dot(mid - pe, ne)), -float(np.dot(mid - px, nx)))
                out.append((angle, centre, w, depth))
    return out


def plan_needle_arc(
    entry: Port,
    exit: Port,  # noqa: A002 - the port's role
    needle: NeedleModel | None = None,
    min_tip_out: float = MIN_TIP_OUT,
    margin: float = 0.001,
    extraction_clearance: float = 0.002,
) -> NeedleArc:
    """Plan the needle circle through ``entry`` and ``exit`` (world port frames).

    Raises :class:`NeedleArcError` with the reason when no circle of the needle radius runs
    through the ports inside the tissue, when the tip cannot get ``min_tip_out`` past the
    exit, or when the needle's arc is too short for the port arc plus the overshoot.
    """
    needle = needle or NeedleModel()
    r = needle.radius
    cands = _candidates(entry, exit, r)
    if not cands:
        raise NeedleArcError(
            f"no circle of radius {1e3 * r:.2f} mm through {entry.name} and {exit.name} "
            "enters against the entry normal and leaves along the exit normal"
        )
    # Shortest sweep first; a tie (the two circles of a symmetric pair sweep the same angle,
    # equal to float noise) goes to the deeper bite, not to whichever rounding came out lower.
    # The first circle on which the whole throw works is the plan.
    failures = []
    for port_angle, centre, w, _ in sorted(cands, key=lambda c: (round(c[0], 6), -c[3])):
        try:
            return _arc_on(
                entry,
                exit,
                needle,
                port_angle,
                centre,
                w,
                min_tip_out,
                margin,
                extraction_clearance,
            )
        except NeedleArcError as e:
            failures.append(e)
    raise failures[0]


def _arc_on(
    entry: Port,
    exit: Port,  # noqa: A002 - the port's role
    needle: NeedleModel,
    port_angle: float,
    centre: np.ndarray,
    w: np.ndarray,
    min_tip_out: float,
    margin: float,
    extraction_clearance: float,
) -> NeedleArc:
    """The throw on one candidate circle, or NeedleArcError saying why it does not work."""
    r = needle.radius
    z = -w  # the tip moves about the needle's −z
    ue = (entry.position - centre) / r
    th = needle.tip_angle
    x = np.cos(th) * ue - np.sin(th) * np.cross(z, ue)
    T0 = np.eye(4)
    T0[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T0[:3, 3] = centre
    # Overshoot: height of the tip above the exit plane after sweeping β past the exit,
    # h(β) = k + r (A cos β + B sin β); solve h(β) = target on the rising side.
    ux = (exit.position - centre) / r
    nx = exit.normal
    k = float(np.dot(centre - exit.position, nx))
    A, B = float(np.dot(ux, nx)), float(np.dot(np.cross(w, ux), nx))
    R, phase = float(np.hypot(A, B)), float(np.arctan2(B, A))
    target = min_tip_out + margin
    if k + r * R < target:
        raise NeedleArcError(
            f"on this circle the tip rises at most {1e3 * (k + r * R):.2f} mm above "
            f"{exit.name}, less than the {1e3 * target:.2f} mm required"
        )
    overshoot = phase - float(np.arccos((target - k) / (r * R)))
    if port_angle + overshoot > needle.arc_angle:
        raise NeedleArcError(
            f"the needle is too short for these ports: its arc is "
            f"{np.rad2deg(needle.arc_angle):.1f}° but the ports need "
            f"{np.rad2deg(port_angle):.1f}° plus {np.rad2deg(overshoot):.1f}° of overshoot"
        )
    return NeedleArc(
        entry,
        exit,
        needle,
        T0,
        port_angle,
        overshoot,
        target,
        extraction_clearance / r,
    )
