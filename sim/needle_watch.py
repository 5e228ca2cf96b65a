"""Feeding the phantom's bookkeeping from the needle: when to run it, and the tip to give it.

Kept out of :mod:`suture_bt.sim.world`, which only calls it after physics. The port
crossing/strain bookkeeping (:meth:`PhantomBody.update`, ~0.8 ms) runs only while the needle's
centre of mass is near a port and the needle moved; the tissue-entry tracker
(:meth:`PhantomBody.track_tip`, a few µs) follows the tip anywhere, the tip computed from the
needle body's base state in plain Python (no matrix per update). A needle at rest changes no
record.
"""

from __future__ import annotations

import numpy as np
import pybullet as pb

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.sim.needle_body import NeedleBody
from suture_bt.sim.phantom_body import PhantomBody
from suture_bt.transforms import invert, make_transform, matrix_from_quat_xyzw

#: The phantom's crossing/strain bookkeeping runs while the needle's centre of mass is within
#: this distance of a port: every centre-line point is within 9.6 mm of the centre of mass, and
#: crossings are captured within 10 mm of a port (engagement within 5 mm), plus a 7 mm margin;
#: farther away nothing can cross or engage.
PORT_WATCH_RADIUS = 0.027


class NeedleWatch:
    """Decides when the phantom's bookkeeping runs and hands it the needle pose and tip."""

    def __init__(self, client: int, phantom: PhantomModel, needle_model: NeedleModel) -> None:
        self._client = client
        self._needle_model = needle_model
        self._port_positions = np.array([p.position for p in phantom.ports()])
        self._phantom_tracking = False
        self._last_needle_state: np.ndarray | None = None
        self._tip_in_com: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def start(self, needle: NeedleBody, phantom: PhantomBody) -> None:
        """First sample at t = 0: crossings if near a port; the tip's place, recording nothing.

        The tip is kept in the needle body's base (COM) frame, so it follows from the base
        state read anyway; a tip that starts inside the tissue is no entry.
        """
        if self._needle_near_ports(needle)[0]:
            phantom.update(needle.pose(), 0.0)
            self._phantom_tracking = True
        state = self._last_needle_state
        T_world_com = make_transform(matrix_from_quat_xyzw(state[3:]), state[:3])
        T_com_needle = invert(T_world_com) @ needle.pose()
        self._tip_in_com = tuple(
            float(v) for v in T_com_needle[:3, :3] @ self._needle_model.tip + T_com_needle[:3, 3]
        )
        phantom.track_tip(self._needle_tip(), 0.0)

    def update(self, needle: NeedleBody, phantom: PhantomBody, t: float) -> None:
        """After physics (needle pose exact): tissue entries, then crossings and strain."""
        if needle.frozen:
            phantom.track_tip(None, t)  # the tissue holds it: the tip stays put
            return
        near, moved = self._needle_near_ports(needle)
        # Tissue entries anywhere on the phantom (a few µs, only when the needle moved).
        phantom.track_tip(self._needle_tip() if moved else None, t)
        if near and (moved or not self._phantom_tracking):
            phantom.update(needle.pose(), t)
            self._phantom_tracking = True
        elif not near and self._phantom_tracking:
            # Far from every port nothing can cross or engage; start afresh when back.
            phantom.reset_tracking()
            phantom.strain = {}
            self._phantom_tracking = False

    def _needle_near_ports(self, needle: NeedleBody) -> tuple[bool, bool]:
        """(near, moved): whether the needle is close enough to a port to cross or strain it,
        and whether it moved since the last call (a needle at rest changes no record)."""
        com, quat = pb.getBasePositionAndOrientation(needle.id, physicsClientId=self._client)
        state = np.r_[com, quat]
        moved = self._last_needle_state is None or bool(
            np.abs(state - self._last_needle_state).max() > 1e-9
        )
        self._last_needle_state = state
        d2 = np.sum((self._port_positions - state[:3]) ** 2, axis=1)
        return bool(d2.min() < PORT_WATCH_RADIUS**2), moved

    def _needle_tip(self) -> tuple[float, float, float]:
        """World needle tip from the base state of the last :meth:`_needle_near_ports` call
        (quaternion rotation in plain Python: no matrix per bookkeeping update)."""
        px, py, pz, qx, qy, qz, qw = self._last_needle_state.tolist()
        vx, vy, vz = self._tip_in_com
        tx, ty, tz = 2 * (qy * vz - qz * vy), 2 * (qz * vx - qx * vz), 2 * (qx * vy - qy * vx)
        return (
            px + vx + qw * tx + qy * tz - qz * ty,
            py + vy + qw * ty + qz * tx - qx * tz,
            pz + vz + qw * tz + qx * ty - qy * tx,
        )
