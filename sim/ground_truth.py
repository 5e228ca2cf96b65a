"""THE ground-truth API of the simulation: for scoring, data generation and tests only.

Honesty boundary (DESIGN.md §3): the true needle pose, true joint positions, true joint
offsets, segmentation masks and the phantom's crossing and tissue-entry records are reachable
through this module and nowhere else. Skills, behaviours, trees and the core's algorithms must
never import it (``tests/test_honesty_boundary.py`` enforces this). An "oracle" mode that feeds
these values to skills, for ablation, must be built in the front door on top of this module and
be labelled as oracle in every output; it is never the default.
"""

from __future__ import annotations

import numpy as np

from suture_bt.kinematics import forward_kinematics
from suture_bt.transforms import invert


class GroundTruth:
    """Read-only access to the true state of a :class:`~suture_bt.sim.world.World`."""

    def __init__(self, world):
        self._world = world

    # ---------------------------------------------------------------- arms
    def joint_positions(self, arm: str) -> np.ndarray:
        """True joint positions q_actual (what the encoders would read without the bias)."""
        return self._world.arms[arm]._true_jp()

    def joint_offset(self, arm: str) -> np.ndarray:
        """The hidden offset Δq (6 values; joints 1-3 non-zero)."""
        return self._world.arms[arm]._true_offset()

    def tip_pose_base(self, arm: str) -> np.ndarray:
        """True tool-tip pose in the arm's base (RCM) frame."""
        return forward_kinematics(self.joint_positions(arm))

    def tip_pose_world(self, arm: str) -> np.ndarray:
        """True tool-tip pose in the world."""
        return self._world.arms[arm].base_frame() @ self.tip_pose_base(arm)

    def servo_plant(self, arm: str):
        """The low-level servo plant of ``arm`` (per-joint bandwidth, damping, friction, load;
        drawn from ``faults.servo`` ranges when the scene has them): never told to control."""
        return self._world.arms[arm]._servo.plant

    def jaw_angle(self, arm: str) -> float:
        """True jaw opening (rad)."""
        return float(self._world.arms[arm].jaw.measured_jp()[0])

    # ---------------------------------------------------------------- needle
    def _needle(self):
        if self._world.needle is None:
            raise RuntimeError("this world has no needle")
        return self._world.needle

    def needle_pose(self) -> np.ndarray:
        """True needle pose (world; frame at the arc centre, arc in its x-y plane)."""
        return self._needle().pose()

    def needle_pose_in_camera(self, eye: str = "left") -> np.ndarray:
        """True needle pose in an eye's OpenCV camera frame."""
        cam = self._world.camera.model.left if eye == "left" else self._world.camera.model.right
        return invert(cam.T_world_cam) @ self.needle_pose()

    def needle_scored_points(self) -> dict[str, np.ndarray]:
        """SRC Task-1 base/mid/tip points of the true needle (world)."""
        return self._world.task.needle.scored_points(self.needle_pose())

    def needle_tip(self) -> np.ndarray:
        """True needle tip (world). A held needle is placed exactly on its jaw: between the
        world's bookkeeping updates the pybullet body lags a moving jaw by up to ~0.1 mm."""
        needle, holder = self._needle(), self._world.needle_holder
        T = needle.pose() if holder is None else self.tip_pose_world(holder) @ needle.T_link_needle
        return T[:3, :3] @ self._world.task.needle.tip + T[:3, 3]

    def needle_holder(self) -> str | None:
        """Name of the arm holding the needle, or None."""
        return self._world.needle_holder

    def needle_holders(self) -> list[str]:
        """All arms whose jaws hold the needle (two during a handover), latest grasp last."""
        return list(self._world.needle_holders)

    # ---------------------------------------------------------------- faults
    def fault_events(self) -> list:
        """Every fault that fired so far (:class:`~suture_bt.sim.faults.FaultEvent`: kind,
        time, source, arm, params), in order; ``servo_model`` events (t = 0) hold each arm's
        drawn servo plant. Evaluation and tests only: skills must never see this."""
        return list(self._world.faults.fired)

    def pending_faults(self) -> list[tuple[float, str]]:
        """Faults scheduled but not fired yet (a slip or drop waits for a held needle)."""
        return self._world.faults.pending()

    # ---------------------------------------------------------------- camera
    def segmentation(self, eye: str = "left") -> dict[str, np.ndarray]:
        """Boolean masks per object ("needle", "psm1", "psm2", "phantom") rendered for one eye."""
        return self._world.segmentation_masks(eye)

    # ---------------------------------------------------------------- phantom
    def port_crossings(self) -> list:
        """Every needle-tip crossing of a port recorded so far (SRC sign convention)."""
        if self._world.phantom is None:
            raise RuntimeError("this world has no phantom body")
        return list(self._world.phantom.crossings)

    def tissue_entries(self) -> list:
        """Every place the needle tip went into the tissue so far, anywhere on the phantom
        (:class:`~suture_bt.sim.phantom_body.TissueEntry`: time, point, nearest port, depth)."""
        if self._world.phantom is None:
            raise RuntimeError("this world has no phantom body")
        return list(self._world.phantom.tissue_entries)

    def phantom_state(self):
        """The phantom body's bookkeeping (crossings, overshoot past exits, tissue strain)."""
        if self._world.phantom is None:
            raise RuntimeError("this world has no phantom body")
        return self._world.phantom
