"""Rerun recordings of runs: the observer's rerun sink, the default blueprint, and the reader
behind ``suture-bt inspect``.

Pure logging: this package never imports the simulator. Ground truth reaches it only through
a feed the front door builds (``suture_bt.runtime.recording``) and is logged only under
``ground_truth/``.
"""
