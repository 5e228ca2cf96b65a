"""Tree factories: ``create_tree(...)`` for the full suture, one throw, calibration, ..."""
