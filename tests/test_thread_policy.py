"""Importing suture_bt asks OpenMP threads to sleep when idle (shared CPUs), unless the user
chose otherwise."""

import os
import subprocess
import sys

SHOW = "import suture_bt, os; print(os.environ['OMP_WAIT_POLICY'])"


def _policy(env: dict) -> str:
    out = subprocess.run(
        [sys.executable, "-c", SHOW], env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


def test_idle_openmp_threads_sleep_by_default():
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    assert _policy(env) == "PASSIVE"


def test_a_policy_the_user_set_is_kept():
    env = dict(os.environ, OMP_WAIT_POLICY="ACTIVE")
    assert _policy(env) == "ACTIVE"
