"""Evaluation campaigns (front door): seeded randomized trials, a crash-isolated runner on
local processes or Ray, and the campaign report (``suture-bt eval``, issue 18).

Importing this package loads neither pybullet nor torch: the trial itself
(:mod:`suture_bt.campaign.trial`) imports the simulator when a worker runs it.
"""
