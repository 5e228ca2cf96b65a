"""numba's on-disk cache for the localiser's kernels, kept fresh by every source they may call.

numba stamps a cached kernel with its own source file only, yet a kernel compiles the kernels
it calls (in other files) into its own machine code. Change a callee's file and its callers'
cached code stays the old one: in session 52 a change to ``fit_terms.py`` left the cached
solver trial (``lm_step.py``) linked to the old terms, and a later call failed inside numba
("'descr' is NULL"); a change of arithmetic would have run stale code without an error. An
upgrade that leaves a ``__pycache__`` behind is the same case for a user.

Here a kernel's stamp is its own file's (numba's) together with a digest of every Python
source in its file's folder (for the localiser's kernels: ``suture_bt/perception``, where all
of them and their callees live): any change there recompiles those kernels once. The
locators are numba's own, in numba's order (a ``NUMBA_CACHE_DIR`` the user set first), with
that stamp (``tests/test_kernel_cache.py`` changes a callee and sees its caller follow).
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Any

from numba.core.caching import (
    CompileResultCacheImpl,
    FunctionCache,
    InTreeCacheLocator,
    UserProvidedCacheLocator,
    UserWideCacheLocator,
)


def sources_digest(folder: Path) -> str:
    """SHA-256 over the names and contents of ``folder``'s ``*.py`` files (sorted)."""
    return _digest(Path(folder).resolve(), _stamps(Path(folder).resolve()))


def _stamps(folder: Path) -> tuple:
    """(name, modification time, size) of each ``*.py`` file, sorted by name."""
    files = sorted(folder.glob("*.py"))
    return tuple((p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in files)


@functools.lru_cache(maxsize=64)
def _digest(folder: Path, stamps: tuple) -> str:
    """The digest, read again only when a file's time or size moved (as numba's own)."""
    h = hashlib.sha256()
    for name, _, _ in stamps:
        h.update(name.encode())
        h.update((folder / name).read_bytes())
    return h.hexdigest()


class _PackageStamp:
    """A locator mixin: numba's stamp of the kernel's own file, and its folder's digest."""

    _py_file: str

    def get_source_stamp(self) -> Any:
        return (super().get_source_stamp(), sources_digest(Path(self._py_file).parent))


class _UserProvided(_PackageStamp, UserProvidedCacheLocator):
    pass


class _InTree(_PackageStamp, InTreeCacheLocator):
    pass


class _UserWide(_PackageStamp, UserWideCacheLocator):
    pass


class _PackageStampedImpl(CompileResultCacheImpl):
    _locator_classes = [_UserProvided, _InTree, _UserWide]


class PackageStampedCache(FunctionCache):
    """numba's function cache with :class:`_PackageStamp` locators."""

    _impl_class = _PackageStampedImpl


def cache_by_package(dispatcher: Any) -> Any:
    """Give a numba dispatcher (compiled without numba's own cache) the package-stamped
    on-disk cache; returns it."""
    dispatcher._cache = PackageStampedCache(dispatcher.py_func)
    return dispatcher
