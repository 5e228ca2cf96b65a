"""Joint-offset calibration from one monocular image (DESIGN.md §1, §5): jaw keypoints at a fixed
calibration pose, a keypoint CNN, an MLP offset regressor and a geometric (PnP) baseline."""
