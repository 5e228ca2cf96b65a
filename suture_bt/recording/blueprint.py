"""The default rerun blueprint: everything a run shows, on one screen.

Left: the 3D scene above the two endoscope images and the calibration images. Right: one
status lane per node, the tree text and the logs (tabs), and the plots (tabs).
"""

from __future__ import annotations

import rerun.blueprint as rrb


def default_blueprint() -> rrb.Blueprint:
    """The layout the recording is saved with (see the module docstring)."""
    scene = rrb.Spatial3DView(
        name="scene (world; ground truth labelled)",
        origin="/",
        contents=["+ /world/**", "+ /ground_truth/world/**"],
    )
    images = rrb.Horizontal(
        rrb.Spatial2DView(name="left eye", origin="/world/camera/left/image"),
        rrb.Spatial2DView(name="right eye", origin="/world/camera/right/image"),
        rrb.Spatial2DView(name="calibration", origin="/camera/calibration"),
    )
    lanes = rrb.StateTimelineView(name="node status", origin="/bt/nodes")
    text = rrb.Tabs(
        rrb.TextDocumentView(name="tree", origin="/bt/tree"),
        rrb.TextLogView(
            name="log", origin="/bt", contents=["+ /bt/log", "+ /bt/checks", "+ /bt/refusals"]
        ),
        rrb.TextLogView(name="blackboard", origin="/bt/blackboard"),
        rrb.TextLogView(name="ground truth log", origin="/ground_truth/log"),
        rrb.TextDocumentView(name="run", origin="/run"),
    )
    plots = rrb.Tabs(
        rrb.TimeSeriesView(name="tracking error", origin="/plots/tracking_error"),
        rrb.TimeSeriesView(name="PI output", origin="/plots/pi_output"),
        rrb.TimeSeriesView(name="lateral error (truth)", origin="/ground_truth/plots/lateral_mm"),
        rrb.TimeSeriesView(name="strain (truth)", origin="/ground_truth/plots/strain_mm"),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(scene, images, row_shares=[3, 2]),
            rrb.Vertical(lanes, text, plots, row_shares=[3, 2, 2]),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="tick"),
    )
