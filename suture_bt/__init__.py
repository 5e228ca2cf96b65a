"""suture-bt: behaviour-tree autonomous suturing with two dVRK PSMs in pybullet.

The top-level package holds the algorithms (kinematics, perception, calibration, planning,
control) and the robot interface; ``suture_bt.sim`` is the pybullet world, and
``suture_bt.skills`` / ``behaviours`` / ``trees`` build the behaviour tree on top.
"""

import os

__version__ = "0.1.0"

# OpenMP threads that have finished a parallel region (torch's, and the compiled pose fit's)
# sleep instead of spinning: on a shared 2-core machine spinning threads starve the other
# processes' (a 2-worker campaign beside the localiser made it 2-5× slower). Set before torch
# or numba load their OpenMP runtime, so it only takes effect when suture_bt is imported first;
# a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
