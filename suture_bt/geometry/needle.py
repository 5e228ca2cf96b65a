"""The SRC suturing needle: a circular arc in the x-y plane of its frame (DESIGN.md §5).

The needle frame sits at the arc centre. The base end is at angle 180° (−r, 0, 0), the tip at
about 56.6°; the arc runs through the +y half-plane. Inserting drives the tip forward, i.e.
rotates the needle about its own −z axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: SRC Task-1 scoring points in the needle frame (metres).
SCORED_POINTS = {
    "base": np.array([-0.0102, 0.0, 0.0]),
    "mid": np.array([-0.0048, 0.0093, 0.0]),
    "tip": np.array([0.0056, 0.0085, 0.0]),
}


@dataclass(frozen=True)
class NeedleModel:
    """Arc radius, end angles and wire radius, in metres and radians."""

    radius: float = 0.01018
    base_angle: float = np.pi
    tip_angle: float = float(np.arctan2(0.0085, 0.0056))
    wire_radius: float = 0.00036

    @property
    def arc_angle(self) -> float:
        """Angle subtended by the arc (≈ 123°)."""
        return self.base_angle - self.tip_angle

    @property
    def length(self) -> float:
        return self.radius * self.arc_angle

    @property
    def chord(self) -> float:
        """Straight-line distance between base and tip (m): the needle's largest extent."""
        return float(2.0 * self.radius * np.sin(0.5 * self.arc_angle))

    def point_at(self, angle) -> np.ndarray:
        """Points on the centre-line (needle frame) at the given arc angle(s)."""
        a = np.asarray(angle, dtype=float)
        return np.stack([self.radius * np.cos(a), self.radius * np.sin(a), np.zeros_like(a)], -1)

    def tangent_at(self, angle) -> np.ndarray:
        """Unit direction of travel of the tip (decreasing angle) at the given angle(s)."""
        a = np.asarray(angle, dtype=float)
        return np.stack([np.sin(a), -np.cos(a), np.zeros_like(a)], -1)

    def centerline(self, n: int = 64) -> np.ndarray:
        """n points (needle frame) from base to tip."""
        return self.point_at(np.linspace(self.base_angle, self.tip_angle, n))

    @property
    def tip(self) -> np.ndarray:
        return self.point_at(self.tip_angle)

    @property
    def base(self) -> np.ndarray:
        return self.point_at(self.base_angle)

    def swap_rotation(self) -> np.ndarray:
        """The half turn (needle frame) about the arc's bisector that exchanges base and tip:
        the same outline, ends swapped (an arc angle a goes to base + tip - a)."""
        mid = 0.5 * (self.base_angle + self.tip_angle)
        axis = np.array([np.cos(mid), np.sin(mid), 0.0])
        return 2.0 * np.outer(axis, axis) - np.eye(3)

    def swapped(self, T_needle: np.ndarray) -> np.ndarray:
        """The pose with base and tip exchanged (the arc centre and outline stay put)."""
        T = np.array(T_needle, dtype=float)
        T[..., :3, :3] = T[..., :3, :3] @ self.swap_rotation()
        return T

    def swapped_angle(self, arc_angle: float) -> float:
        """The arc angle a place on the needle takes when base and tip are exchanged."""
        return self.base_angle + self.tip_angle - arc_angle

    def scored_points(self, T_world_needle: np.ndarray) -> dict[str, np.ndarray]:
        """SRC base/mid/tip scoring points in the world for a needle pose."""
        R, p = T_world_needle[:3, :3], T_world_needle[:3, 3]
        return {k: R @ v + p for k, v in SCORED_POINTS.items()}
