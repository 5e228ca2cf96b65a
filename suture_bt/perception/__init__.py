"""Needle perception: multi-task CNN, colour refinement, stereo pose fit, in-hand estimation."""
