"""Shared by the recovery-branch tests: a real single-throw session, its nodes, stop
predicates and verdicts, and small rotations for building needle poses."""

import numpy as np
from py_trees.common import Status

from suture_bt.runtime.session import RunOptions, Session


def single_throw_session():
    """A real single-throw session, closed afterwards (the test files' ``session`` fixture)."""
    s = Session(RunOptions(tree="single_throw"))
    yield s
    s.close()


def node(session, name: str):
    """The tree's node called ``name`` (the first, depth first)."""
    return next(n for n in session.root.iterate() if n.name == name)


def running(session, name: str, says: str = ""):
    """A stop predicate: node ``name`` runs and its feedback contains ``says``."""

    def hit(s) -> bool:
        n = node(s, name)
        return n.status == Status.RUNNING and says in (n.feedback_message or "")

    return hit


def finish(session) -> dict:
    session.run()
    assert session.error is None, session.error
    return session.context.throws[1]


def passed(session) -> bool:
    return bool(session.scores()[0].passed)


#: The in-hand check before the first insertion: PSM2 moves the needle over entry 1 for it.
CHECK_1 = "Needle still as held? (pair 1)"


def ran(session, name: str) -> list[tuple[int, str, Status]]:
    """(attempt, child, status) of every child RecoveryNode ``name`` finished."""
    return [(a, child, status) for a, child, status, _ in node(session, name).history]


def pose(R: np.ndarray, p) -> np.ndarray:
    T = np.array(R, dtype=float)
    T[:3, 3] = p
    return T


def rot_z(a: float) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return T


def rot_x(a: float) -> np.ndarray:
    T = np.eye(4)
    T[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return T
