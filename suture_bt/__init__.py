"""suture-bt: behaviour-tree autonomous suturing with two dVRK PSMs in pybullet.

The top-level package holds the algorithms (kinematics, perception, calibration, planning,
control) and the robot interface; ``suture_bt.sim`` is the pybullet world, and
``suture_bt.skills`` / ``behaviours`` / ``trees`` build the behaviour tree on top.
"""

import os

__version__ = "0.1.0"

# OpenMP threads that have finished a parallel region (torch's, and the compiled pose fit's)
# spin only briefly before they sleep (GNU OpenMP's default spins far longer): on a shared
# 2-core machine long-spinning threads starve the other processes'. Development task frames,
# ms per stereo frame (mean / p95): idle 64 / 77 by default, 68 / 79 with this; beside two
# busy processes 403 / 904 by default, 151 / 218 with this (sleeping at once, PASSIVE: the same
# under load, 84 / 101 idle). Set before torch or numba load their OpenMP runtime, so it only
# takes effect when suture_bt is imported first; a value the user set is kept.
# Session 19: 1000 made the pose fit's compiled kernel, which opens a parallel region per
# Levenberg-Marquardt step, wake its second thread from sleep each time. Development task
# frames (seed 6173, held_start, 10 calls), fit ms idle / whole call mean and p95 beside two
# busy processes: 1000: 74 / 213, 270; 3000: 51 / 218, 236; 10000: 47 / 228, 263; 30000: 43 /
# 337, 494; 300000 (GNU's default): 42 / 532, 1596.
os.environ.setdefault("GOMP_SPINCOUNT", "10000")
