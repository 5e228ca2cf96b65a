"""pybullet's banners are kept off the terminal: the build-time one on import through sim.quiet,
the EGL plugin's on stdout when it renders."""

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


def test_rendering_prints_no_egl_banner_on_stdout():
    """The EGL plugin prints "ven = ..." when it first renders: a benchmark's JSON on stdout
    stays clean (the renderer's calls run with fd 1 silenced)."""
    code = (
        "import numpy as np\n"
        "from suture_bt.datagen.needle_data import SimScene\n"
        "sim = SimScene(320, 240)\n"
        "s = sim.sampler.sample(np.random.default_rng(0))\n"
        "sim.apply(s); sim.render('left', s, np.random.default_rng(0)); sim.close()\n"
        "print('done')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout == "done\n"
