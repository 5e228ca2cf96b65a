"""The kernels' on-disk cache follows every source in a kernel's folder: a caller's cached
code is compiled again when a kernel it calls changes in another file (numba's own stamp
looks at the caller's file alone and would run the old callee)."""

import os
import subprocess
import sys
import textwrap

from suture_bt.perception.fit_terms import away_angle
from suture_bt.perception.kernel_cache import PackageStampedCache, sources_digest

CALLER = """
from suture_bt.perception.compiled import kernel
from kpkg.callee import step

@kernel()
def caller(x):
    return step(x)

print(caller(1.0))
"""


def _write_callee(pkg, add: float) -> None:
    (pkg / "callee.py").write_text(
        "from suture_bt.perception.compiled import kernel\n\n"
        f"@kernel()\ndef step(x):\n    return x + {add}\n"
    )


def _run(tmp_path) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}
    script = tmp_path / "run_caller.py"
    script.write_text("import kpkg.caller\n")
    out = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip()


def test_a_callers_cached_code_follows_its_callee_in_another_file(tmp_path):
    pkg = tmp_path / "kpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(textwrap.dedent(CALLER))
    _write_callee(pkg, 1.0)
    assert _run(tmp_path) == "2.0"
    assert any((tmp_path / "cache").rglob("*.nbi")), "the caller was cached"
    _write_callee(pkg, 2.0)  # the caller's file is unchanged
    assert _run(tmp_path) == "3.0"
    assert _run(tmp_path) == "3.0"


def test_the_digest_covers_names_and_contents_of_the_folders_python_files(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "notes.txt").write_text("not a source")
    first = sources_digest(tmp_path)
    (tmp_path / "notes.txt").write_text("still not a source")
    assert sources_digest(tmp_path) == first
    (tmp_path / "a.py").write_text("x = 2\n")
    second = sources_digest(tmp_path)
    assert second != first
    (tmp_path / "b.py").write_text("")
    assert sources_digest(tmp_path) not in (first, second)


def test_the_localisers_kernels_are_stamped_by_their_package():
    cache = away_angle._cache
    assert isinstance(cache, PackageStampedCache)
    own, package = cache._impl.locator.get_source_stamp()
    assert package == sources_digest(os.path.dirname(away_angle.py_func.__code__.co_filename))
