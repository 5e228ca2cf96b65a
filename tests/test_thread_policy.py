"""Importing suture_bt asks idle OpenMP threads to spin only briefly (shared CPUs), unless
the user chose otherwise."""

import os
import subprocess
import sys

SHOW = "import suture_bt, os; print(os.environ['GOMP_SPINCOUNT'])"


def _policy(env: dict) -> str:
    out = subprocess.run(
        [sys.executable, "-c", SHOW], env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


def test_idle_openmp_threads_spin_briefly_by_default():
    env = {k: v for k, v in os.environ.items() if k != "GOMP_SPINCOUNT"}
    assert _policy(env) == "10000"


def test_a_spin_count_the_user_set_is_kept():
    env = dict(os.environ, GOMP_SPINCOUNT="300000")
    assert _policy(env) == "300000"
