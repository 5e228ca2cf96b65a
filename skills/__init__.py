"""Task-level skills: stepwise, each verifying its own result. Never import sim or pybullet."""
