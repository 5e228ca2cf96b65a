"""pybullet's build-time banner is kept off stderr when imported through sim.quiet."""

import subprocess
import sys


def test_import_prints_no_banner():
    code = "from suture_bt.sim.quiet import import_pybullet_quietly as f; f(); f()"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "pybullet build time" not in out.stderr + out.stdout
    loud = subprocess.run(
        [sys.executable, "-c", "import pybullet"], capture_output=True, text=True, check=True
    )
    assert "pybullet build time" in loud.stderr + loud.stdout  # the banner this hides
