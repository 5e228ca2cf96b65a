"""The suturing phantom's known geometry: 4 entry/exit port pairs on the flanks of a ridge.

Port positions are given in the phantom frame, which coincides with the world frame in the
default SRC scene (DESIGN.md §5). A scene may move and rotate the phantom: everything that
uses ports must go through :meth:`PhantomModel.port_frames` with the scene's phantom pose.
Each port frame has z along the outward surface normal; the needle tip crosses an entry
going from +z to −z and an exit going from −z to +z.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from suture_bt.transforms import make_transform, rpy_to_matrix

ENTRY_X = (-0.00374, -0.00432, -0.00334, -0.00439)
EXIT_X = 0.00408
PAIR_Y = (0.04419, 0.02069, -0.00203, -0.02768)
ENTRY_Z = 0.07500
EXIT_Z = 0.07486
#: Flank pitch about y of the port frames (entries −, exits +).
FLANK_PITCH = np.deg2rad(46.1)
#: Side of the square marking each port.
PORT_MARK_SIZE = 0.005
#: Height of the flat tissue surface (phantom frame) on which the needle rests at start.
TISSUE_TOP_Z = 0.0713
#: Extent of the flat tissue block (phantom frame, m): beyond it a needle falls off the phantom.
TISSUE_X = (-0.045, 0.045)
TISSUE_Y = (-0.055, 0.075)


@dataclass(frozen=True)
class Port:
    """One port: name ("entry1", "exit3", ...), pair index 1..4 and its frame."""

    name: str
    pair: int
    kind: str  # "entry" or "exit"
    T: np.ndarray

    @property
    def position(self) -> np.ndarray:
        return self.T[:3, 3]

    @property
    def normal(self) -> np.ndarray:
        return self.T[:3, 2]

    def tip_pose_into_tissue(self) -> np.ndarray:
        """A tool-tip pose at the port: z into the tissue, x along the port's y (the ridge)."""
        z = -self.normal
        x = self.T[:3, 1] - np.dot(self.T[:3, 1], z) * z
        x /= np.linalg.norm(x)
        return make_transform(np.column_stack([x, np.cross(z, x), z]), self.position)


def default_ports_in_phantom() -> list[Port]:
    """The 8 SRC ports in the phantom frame, ordered entry1, exit1, ..., entry4, exit4."""
    ports = []
    for i, (ex, y) in enumerate(zip(ENTRY_X, PAIR_Y, strict=True), start=1):
        r_entry = rpy_to_matrix((0.0, -FLANK_PITCH, 0.0))
        r_exit = rpy_to_matrix((0.0, FLANK_PITCH, 0.0))
        ports.append(Port(f"entry{i}", i, "entry", make_transform(r_entry, (ex, y, ENTRY_Z))))
        ports.append(Port(f"exit{i}", i, "exit", make_transform(r_exit, (EXIT_X, y, EXIT_Z))))
    return ports


@dataclass(frozen=True)
class PhantomModel:
    """Phantom pose in the world plus its ports (phantom frame)."""

    T_world_phantom: np.ndarray = field(default_factory=lambda: np.eye(4))
    ports_in_phantom: tuple[Port, ...] = field(
        default_factory=lambda: tuple(default_ports_in_phantom())
    )

    def ports(self) -> list[Port]:
        """All ports with world frames."""
        return [
            Port(p.name, p.pair, p.kind, self.T_world_phantom @ p.T) for p in self.ports_in_phantom
        ]

    def port(self, name: str) -> Port:
        for p in self.ports():
            if p.name == name:
                return p
        raise KeyError(f"no port named {name!r}")

    def pair(self, i: int) -> tuple[Port, Port]:
        """(entry, exit) ports of pair i (1-based), world frames."""
        return self.port(f"entry{i}"), self.port(f"exit{i}")

    @property
    def num_pairs(self) -> int:
        return len(self.ports_in_phantom) // 2
