"""The pybullet world: PSMs, needle, phantom, stereo endoscope, faults and ground truth."""
