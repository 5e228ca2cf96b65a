"""Front door: what wires a world to a tree (views of the interfaces, tick loop, debugger).

This is the only layer that touches simulator objects; skills, behaviours and trees get the
interface-only views of :mod:`suture_bt.runtime.views` (DESIGN.md §2-3).
"""
