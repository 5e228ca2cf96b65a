"""suture-bt: behaviour-tree autonomous suturing with two dVRK PSMs in pybullet.

The top-level package holds the algorithms (kinematics, perception, calibration, planning,
control) and the robot interface; ``suture_bt.sim`` is the pybullet world, and
``suture_bt.skills`` / ``behaviours`` / ``trees`` build the behaviour tree on top.
"""

__version__ = "0.1.0"
