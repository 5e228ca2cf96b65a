"""``suture-bt replay run.rrd``: open a saved run in the rerun viewer, when one can start here.

When no viewer can start (no display, no viewer executable) it says why, and how to look at
the run anyway (``suture-bt inspect``, or ``rerun run.rrd`` on a machine with a display).
"""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser("replay", help="open a saved run.rrd in the rerun viewer")
    p.add_argument("rrd", metavar="RUN.rrd", help="a recording saved by run or debug")
    p.set_defaults(func=run)


def run(args) -> int:
    from suture_bt.recording.reader import read_run
    from suture_bt.recording.viewer import open_in_viewer, why_no_viewer

    path = Path(args.rrd)
    rec = read_run(path)  # a missing or unreadable file is one clear line
    span = rec.tick_range
    what = f"ticks {span[0]}..{span[1]}" if span else "no ticks"
    why = why_no_viewer()
    if why is not None:
        raise RuntimeError(
            f"cannot open a viewer here: {why}; read it with 'suture-bt inspect {path}', "
            f"or run 'rerun {path}' where a display is available"
        )
    open_in_viewer(path)
    print(f"opened {path} ({what}) in the rerun viewer")
    return 0
