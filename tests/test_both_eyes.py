"""Both eyes' work at once: results in eye order, errors as if one eye ran after the other."""

import threading
import time

import pytest

from suture_bt.perception import both_eyes as module
from suture_bt.perception.both_eyes import both_eyes


def test_results_come_back_in_eye_order_and_the_right_eye_runs_on_another_thread():
    threads = {}

    def work(eye):
        threads[eye] = threading.get_ident()
        return f"eye {eye}"

    assert both_eyes(work) == ("eye 0", "eye 1")
    assert threads[0] == threading.get_ident()
    assert threads[1] != threads[0]


def test_the_two_eyes_overlap_in_time():
    # Each eye waits for the other to start: run one after the other, this would time out.
    started = [threading.Event(), threading.Event()]

    def work(eye):
        started[eye].set()
        return started[1 - eye].wait(timeout=5.0)

    assert both_eyes(work) == (True, True)


def test_left_error_wins_and_the_right_eye_has_finished_when_it_is_raised():
    finished = []

    def work(eye):
        if eye == 0:
            raise ValueError("left")
        time.sleep(0.05)
        finished.append(eye)
        raise KeyError("right")

    with pytest.raises(ValueError, match="left"):
        both_eyes(work)
    assert finished == [1]


def test_a_right_eye_error_is_raised_when_the_left_eye_succeeds():
    def work(eye):
        if eye == 1:
            raise ValueError("right")
        return eye

    with pytest.raises(ValueError, match="right"):
        both_eyes(work)


def test_a_forked_child_starts_its_own_worker(monkeypatch):
    both_eyes(lambda eye: eye)
    parents = module._POOL
    # A forked child sees the parent's pool object under another process id.
    monkeypatch.setattr(module, "_POOL", (parents[0], parents[1] + 1))
    assert both_eyes(lambda eye: eye) == (0, 1)
    assert module._POOL[0] is not parents[0]
    assert module._POOL[1] == parents[1]
    module._POOL[0].shutdown()
    monkeypatch.undo()
