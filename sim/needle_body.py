"""The needle in pybullet: drawn as its true-thickness mesh, colliding as a chain of spheres.

States: *free* (dynamic: falls and comes to rest on the tissue), *held* (a fixed constraint to
an arm link) and *frozen* (a fixed constraint to the world: the tissue holds an inserted,
released needle). Collisions with the tissue bodies are off while held or frozen (the needle
passes through tissue) and come back once a released needle is clear of them.
"""

from __future__ import annotations

import numpy as np
import pybullet as p

from suture_bt.geometry.needle import NeedleModel
from suture_bt.sim.needle_mesh import write_needle_obj, write_needle_texture
from suture_bt.sim.rendering import load_renderer
from suture_bt.transforms import invert, make_transform, matrix_from_quat_xyzw, quat_xyzw

#: Simulated mass. The real needle weighs about 0.07 g; a heavier one keeps contacts stable at
#: 1 kHz and changes nothing else (the needle is only ever resting, held or frozen).
NEEDLE_MASS = 0.002
#: Collision capsules along the arc's chords (only for contacts; the visual is the exact mesh).
#: pybullet keeps at most 16 children of a compound shape and silently drops the rest.
N_COLLISION_SEGMENTS = 15
#: The texture carries the colours (grey metal, violet base band); this tints it (white: none).
NEEDLE_RGBA = (1.0, 1.0, 1.0, 1.0)
NEEDLE_SPECULAR = (0.9, 0.9, 0.9)
#: Force limit of the grasp/tissue constraints (N): far above the needle's weight.
HOLD_FORCE = 50.0
#: A released needle overlapping the tissue by at most this (m; the wire's radius plus the
#: contact margin and some) is lifted out of it rather than left to pass through.
LIFT_OUT = 0.001


def _check_pose(T, what: str = "needle pose") -> np.ndarray:
    """A finite 4×4 transform as a float array, else a ValueError naming it."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{what} must be a finite 4×4 transform, got shape {T.shape}")
    return T


def _pose(position, quat) -> np.ndarray:
    return make_transform(matrix_from_quat_xyzw(quat), position)


def arc_inertia(model: NeedleModel, mass: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre of mass, principal axes (columns, needle frame) and principal moments of the arc.

    The arc is not symmetric about a needle-frame axis, so its inertia tensor about the COM has
    a large x-y product term; pybullet takes a diagonal in the inertial frame, so that frame is
    put on the principal axes.
    """
    a = np.linspace(model.base_angle, model.tip_angle, 721)
    pts = model.point_at(a)
    com = pts.mean(0)
    d = pts - com
    tensor = (mass / len(pts)) * (np.eye(3) * (d**2).sum() - d.T @ d)
    moments, axes = np.linalg.eigh(tensor)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    ring = 0.5 * mass * model.wire_radius**2  # wire cross-section, keeps all moments > 0
    return com, axes, moments + ring


class NeedleBody:
    """The needle body in one pybullet client (never the default client)."""

    def __init__(
        self,
        client: int,
        model: NeedleModel,
        T_world_needle: np.ndarray,
        tissue_ids: tuple[int, ...] = (),
        mass: float = NEEDLE_MASS,
    ) -> None:
        T_world_needle = _check_pose(T_world_needle)
        if not mass > 0:
            raise ValueError(f"needle mass must be positive, got {mass!r}")
        self.client = client
        self.model = model
        load_renderer(client)  # bodies created before the EGL plugin loads are never drawn
        # The body's base frame is the needle's principal inertial frame (COM, principal axes).
        self._com, axes, inertia = arc_inertia(model, mass)
        self._T_needle_com = make_transform(axes, self._com)
        T_com_needle = invert(self._T_needle_com)
        mesh = write_needle_obj(model)
        vis = p.createVisualShape(
            p.GEOM_MESH,
            fileName=str(mesh),
            meshScale=[1.0, 1.0, 1.0],
            rgbaColor=list(NEEDLE_RGBA),
            specularColor=list(NEEDLE_SPECULAR),
            visualFramePosition=list(T_com_needle[:3, 3]),
            visualFrameOrientation=list(quat_xyzw(T_com_needle[:3, :3])),
            physicsClientId=client,
        )
        ends = model.point_at(
            np.linspace(model.base_angle, model.tip_angle, N_COLLISION_SEGMENTS + 1)
        )
        chords = ends[1:] - ends[:-1]
        lengths = np.linalg.norm(chords, axis=1)
        # Capsule axis is local z: rotate z onto each chord (chords lie in the needle x-y plane).
        quats = []
        for d in chords / lengths[:, None]:
            x = np.cross(d, [0.0, 0.0, 1.0])
            R_needle_capsule = np.stack([x, np.cross(d, x), d], 1)
            quats.append(list(quat_xyzw(T_com_needle[:3, :3] @ R_needle_capsule)))
        col = p.createCollisionShapeArray(
            shapeTypes=[p.GEOM_CAPSULE] * N_COLLISION_SEGMENTS,
            radii=[model.wire_radius] * N_COLLISION_SEGMENTS,
            lengths=list(lengths),
            collisionFramePositions=[
                list(T_com_needle[:3, :3] @ ((a + b) / 2) + T_com_needle[:3, 3])
                for a, b in zip(ends[:-1], ends[1:], strict=True)
            ],
            collisionFrameOrientations=quats,
            physicsClientId=client,
        )
        T_world_com = np.asarray(T_world_needle) @ self._T_needle_com
        self.id = p.createMultiBody(
            baseMass=mass,
            baseCollisionShapeIndex=col,
            baseVisualShapeIndex=vis,
            basePosition=list(T_world_com[:3, 3]),
            baseOrientation=list(quat_xyzw(T_world_com[:3, :3])),
            physicsClientId=client,
        )
        texture = p.loadTexture(str(write_needle_texture()), physicsClientId=client)
        p.changeVisualShape(self.id, -1, textureUniqueId=texture, physicsClientId=client)
        p.changeDynamics(
            self.id,
            -1,
            localInertiaDiagonal=list(inertia),
            lateralFriction=0.8,
            spinningFriction=1e-4,
            rollingFriction=1e-4,
            linearDamping=0.1,
            angularDamping=0.1,
            physicsClientId=client,
        )
        self._tissue: list[int] = []
        self._tissue_enabled = True
        self._constraint: int | None = None
        self._held_by: tuple[int, int] | None = None
        self._T_link_needle: np.ndarray | None = None
        self._frozen = False
        self._pending_tissue = False
        for b in tissue_ids:
            self.add_tissue(b)

    # --- pose -------------------------------------------------------------------------------
    def pose(self) -> np.ndarray:
        """World pose (4×4) of the needle frame (arc centre)."""
        pos, quat = p.getBasePositionAndOrientation(self.id, physicsClientId=self.client)
        return _pose(pos, quat) @ invert(self._T_needle_com)

    def set_pose(self, T_world_needle: np.ndarray) -> None:
        """Teleport the needle (velocity zeroed); a held or frozen needle keeps its constraint."""
        T_world_needle = _check_pose(T_world_needle)
        T = T_world_needle @ self._T_needle_com
        p.resetBasePositionAndOrientation(
            self.id, list(T[:3, 3]), list(quat_xyzw(T[:3, :3])), physicsClientId=self.client
        )
        p.resetBaseVelocity(self.id, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        if self._frozen and self._constraint is not None:
            self._fix_to_world(np.asarray(T_world_needle))

    def velocity(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear (m/s) and angular (rad/s) velocity of the needle body."""
        v, w = p.getBaseVelocity(self.id, physicsClientId=self.client)
        return np.array(v), np.array(w)

    def is_resting(self, lin_tol: float = 1e-3, ang_tol: float = 0.05) -> bool:
        """True when the needle is (nearly) motionless."""
        v, w = self.velocity()
        return bool(np.linalg.norm(v) < lin_tol and np.linalg.norm(w) < ang_tol)

    # --- state ------------------------------------------------------------------------------
    @property
    def held_by(self) -> tuple[int, int] | None:
        """(body id, link index) of the holder, or None."""
        return self._held_by

    @property
    def T_link_needle(self) -> np.ndarray | None:
        """In-hand pose of the needle in the holding link's frame (None when not held)."""
        return None if self._T_link_needle is None else self._T_link_needle.copy()

    @property
    def frozen(self) -> bool:
        return self._frozen

    @property
    def state(self) -> str:
        """ "held", "frozen" or "free"."""
        return "held" if self._held_by else ("frozen" if self._frozen else "free")

    # --- collisions -------------------------------------------------------------------------
    def add_tissue(self, body_id: int) -> None:
        """Declare a body the needle passes through while held or frozen (e.g. the phantom)."""
        self._tissue.append(body_id)
        self._set_tissue_collision(self._tissue_enabled, [body_id])

    def ignore_collisions_with(self, body_id: int) -> None:
        """Never collide with this body (e.g. the arms, which are reset kinematically)."""
        self._filter(body_id, False)

    def _filter(self, body_id: int, enable: bool) -> None:
        n = p.getNumJoints(body_id, physicsClientId=self.client)
        for link in range(-1, n):
            p.setCollisionFilterPair(
                self.id, body_id, -1, link, int(enable), physicsClientId=self.client
            )

    def _set_tissue_collision(self, enable: bool, bodies=None) -> None:
        for b in self._tissue if bodies is None else bodies:
            self._filter(b, enable)
        self._tissue_enabled = enable

    def _penetrates_tissue(self) -> bool:
        return self._penetration() > 1e-5

    def _penetration(self) -> float:
        """Deepest overlap (m) of the needle's collision shape with a tissue body (0: none)."""
        deepest = 0.0
        for b in self._tissue:
            for c in p.getClosestPoints(self.id, b, 0.0, physicsClientId=self.client):
                deepest = max(deepest, -float(c[8]))
        return deepest

    def update(self) -> None:
        """Call after every physics step: a held needle is snapped exactly onto its holder (the
        constraint alone lags a moving, kinematically reset arm by ~0.1-0.3 mm); a released
        needle gets its tissue contacts back once it is clear of the tissue."""
        if self._held_by is not None:
            self.sync_to_holder()
        if self._pending_tissue and self.state == "free" and not self._penetrates_tissue():
            self._set_tissue_collision(True)
            self._pending_tissue = False

    def _release_collisions(self) -> None:
        """After a release: collide with tissue again now. A needle whose collision shape only
        overlaps the tissue (by at most ``LIFT_OUT``: released against it, not stuck in it) is
        first lifted straight up out of the overlap, as the tissue would push it; with its
        contacts off it would fall through the tissue (a campaign trial's dropped needle ended
        under the phantom and was scored a stab). One deeper in gets its contacts back once it
        is clear of the tissue."""
        self._set_tissue_collision(True)
        for _ in range(4):
            depth = self._penetration()
            if depth <= 1e-5:
                self._pending_tissue = False
                return
            if depth > LIFT_OUT:
                break
            T = self.pose()
            T[2, 3] += 1.5 * depth + 1e-4  # a 46° flank needs about 1.44× the overlap
            self.set_pose(T)
        self._set_tissue_collision(False)
        self._pending_tissue = True

    # --- constraints ------------------------------------------------------------------------
    def _remove_constraint(self) -> None:
        if self._constraint is not None:
            p.removeConstraint(self._constraint, physicsClientId=self.client)
            self._constraint = None

    def _link_pose(self, body: int, link: int) -> np.ndarray:
        """World pose of a link frame (URDF link frame, not its inertial frame)."""
        if link < 0:
            pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
            return _pose(pos, quat) @ invert(self._inertial_offset(body, link))
        s = p.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=self.client)
        return _pose(s[4], s[5])

    def _inertial_offset(self, body: int, link: int) -> np.ndarray:
        """Pose of a link's inertial (COM) frame in its link frame."""
        info = p.getDynamicsInfo(body, link, physicsClientId=self.client)
        return _pose(info[3], info[4])

    def attach(self, parent_body: int, parent_link: int, T_link_needle: np.ndarray) -> None:
        """Hold the needle rigidly at ``T_link_needle`` in the parent link's frame."""
        T_link_needle = _check_pose(T_link_needle, "T_link_needle")
        self._remove_constraint()
        self._frozen = False
        self._set_tissue_collision(False)
        self._pending_tissue = False
        self.set_pose(self._link_pose(parent_body, parent_link) @ T_link_needle)
        # Constraint frames are given in the parent's and child's inertial (COM) frames.
        T_pcom_ccom = (
            invert(self._inertial_offset(parent_body, parent_link))
            @ T_link_needle
            @ self._T_needle_com
        )
        self._constraint = p.createConstraint(
            parentBodyUniqueId=parent_body,
            parentLinkIndex=parent_link,
            childBodyUniqueId=self.id,
            childLinkIndex=-1,
            jointType=p.JOINT_FIXED,
            jointAxis=[0, 0, 0],
            parentFramePosition=list(T_pcom_ccom[:3, 3]),
            parentFrameOrientation=list(quat_xyzw(T_pcom_ccom[:3, :3])),
            childFramePosition=[0, 0, 0],
            childFrameOrientation=[0, 0, 0, 1],
            physicsClientId=self.client,
        )
        p.changeConstraint(self._constraint, maxForce=HOLD_FORCE, physicsClientId=self.client)
        self._held_by = (parent_body, parent_link)
        self._T_link_needle = T_link_needle.copy()

    def detach(self) -> None:
        """Let go: the needle becomes free (falls) unless the caller freezes it."""
        if self._held_by is None:
            return
        self._remove_constraint()
        self._held_by = None
        self._T_link_needle = None
        self._release_collisions()

    def sync_to_holder(self) -> None:
        """Snap a held needle exactly onto its holder (removes constraint lag after a reset)."""
        if self._held_by is not None and self._T_link_needle is not None:
            body, link = self._held_by
            T = self._link_pose(body, link) @ self._T_link_needle
            Tc = T @ self._T_needle_com
            p.resetBasePositionAndOrientation(
                self.id, list(Tc[:3, 3]), list(quat_xyzw(Tc[:3, :3])), physicsClientId=self.client
            )

    def _fix_to_world(self, T_world_needle: np.ndarray) -> None:
        self._remove_constraint()
        Tc = T_world_needle @ self._T_needle_com
        self._constraint = p.createConstraint(
            parentBodyUniqueId=self.id,
            parentLinkIndex=-1,
            childBodyUniqueId=-1,
            childLinkIndex=-1,
            jointType=p.JOINT_FIXED,
            jointAxis=[0, 0, 0],
            parentFramePosition=[0, 0, 0],
            parentFrameOrientation=[0, 0, 0, 1],
            childFramePosition=list(Tc[:3, 3]),
            childFrameOrientation=list(quat_xyzw(Tc[:3, :3])),
            physicsClientId=self.client,
        )
        p.changeConstraint(self._constraint, maxForce=HOLD_FORCE, physicsClientId=self.client)

    def freeze(self, T_world_needle: np.ndarray | None = None) -> None:
        """The tissue holds the needle where it is (or at ``T_world_needle``); drops any holder."""
        T = self.pose() if T_world_needle is None else _check_pose(T_world_needle)
        self._remove_constraint()
        self._held_by = None
        self._T_link_needle = None
        self._set_tissue_collision(False)
        self._pending_tissue = False
        self._frozen = True
        self.set_pose(T)
        self._fix_to_world(T)

    def unfreeze(self) -> None:
        """The tissue lets go (the needle is free again)."""
        if not self._frozen:
            return
        self._remove_constraint()
        self._frozen = False
        self._release_collisions()
