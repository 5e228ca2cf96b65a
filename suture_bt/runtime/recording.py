"""Wire a rerun recording to a session (``--rerun save|spawn|off``), with its ground-truth feed.

``save`` writes ``DIR/run.rrd`` with the default blueprint; ``spawn`` also streams to a viewer
it starts (and says so, saving only, when no viewer can start here). The ground truth the
recording shows comes from :class:`TruthFeed`, built here in the front door, and goes only
under ``ground_truth/``.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from suture_bt.recording.blueprint import default_blueprint
from suture_bt.recording.scene_sink import SceneSink
from suture_bt.recording.tree_sink import Flush, TreeSink
from suture_bt.recording.viewer import why_no_viewer
from suture_bt.sim.ground_truth import GroundTruth

MODES = ("save", "spawn", "off")
APPLICATION = "suture-bt"


class TruthFeed:
    """What the recording's ``ground_truth/`` entities show, read from the world's truth."""

    def __init__(self, world: Any):
        self._truth = GroundTruth(world)

    def needle_pose(self) -> np.ndarray | None:
        try:
            return self._truth.needle_pose()
        except RuntimeError:  # a world without a needle
            return None

    def joint_positions(self, arm: str) -> np.ndarray:
        return self._truth.joint_positions(arm)

    def crossings(self) -> list:
        try:
            return self._truth.port_crossings()
        except RuntimeError:  # a world without a phantom body
            return []

    def strain(self) -> dict[str, float]:
        """Port -> distance (m) from the engaged port to the needle's circle, now."""
        try:
            state = self._truth.phantom_state()
        except RuntimeError:
            return {}
        return {port: float(s.circle) for port, s in state.strain.items()}


def attach_recording(
    session: Any, mode: str, path: Path, say: Callable[[str], None] = print
) -> Path | None:
    """Record ``session`` per ``mode``; the .rrd path (None for ``off``)."""
    if mode not in MODES:
        raise ValueError(f"--rerun must be one of {', '.join(MODES)}, got {mode!r}")
    if mode == "off":
        return None
    opts = session.options
    rec = rr.RecordingStream(
        APPLICATION, recording_id=f"{opts.tree}-seed{session.scene.seed}-{uuid.uuid4().hex[:8]}"
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    blueprint = default_blueprint()
    why = why_no_viewer() if mode == "spawn" else None
    if mode == "spawn" and why is None:
        rec.spawn(connect=False, default_blueprint=blueprint)
        rec.set_sinks(rr.FileSink(str(path)), rr.GrpcSink(), default_blueprint=blueprint)
        say(f"rerun: streaming to a viewer and saving to {path}")
    else:
        if why is not None:
            say(f"rerun: cannot start a viewer here ({why}); saving to {path} only")
        rec.save(path, default_blueprint=blueprint)
    session.observer.add(TreeSink(rec))
    session.observer.add(SceneSink(rec, truth=TruthFeed(session.world)))
    session.observer.add(Flush(rec))  # last: closes after the others flushed
    return path
