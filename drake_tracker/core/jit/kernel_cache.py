"""Keeps numba's on-disk cache of this package's kernels consistent with their sources.

numba's cache keys a compiled function by its own source file's time stamp, not by the
files of the functions and intrinsics it calls: a kernel whose file did not change is
loaded from the cache with the code of a callee (in another file) that did. After a
``git pull`` that changes, say, ``simd/lanes.py`` but not ``render/fused_score.py``,
that would run stale code (and can crash). :func:`clear_stale_kernel_cache`, run when
``drake_tracker.core`` is imported (before any kernel is called), hashes the sources of
every module of ``drake_tracker.core`` (its subpackages included) and empties their
numba caches, and the bench's (its kernels call these), when they changed since they
were filled. A cache
elsewhere (numba's fallback for an unwritable package folder, or ``NUMBA_CACHE_DIR``)
is left alone: there, a release's files change together.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

_FOLDER = Path(__file__).resolve().parents[1]  # drake_tracker/core
_STAMP = "kernel_sources.sha256"


def sources_hash(folder: Path = _FOLDER) -> str:
    """SHA-256 of the Python sources below ``folder`` (subfolders included), in path
    order."""
    digest = hashlib.sha256()
    for path in sorted(folder.rglob("*.py")):
        digest.update(str(path.relative_to(folder)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def clear_stale_kernel_cache(folder: Path = _FOLDER,
                             callers: tuple[Path, ...] = (_FOLDER.parent / "bench",)) -> bool:
    """Removes the numba cache files (``*.nbi``, ``*.nbc``) of every ``__pycache__``
    below ``folder``, and below each ``callers`` folder (kernels there call this folder's,
    e.g. the bench's replay of the scoring kernel), if the sources below ``folder`` changed since
    the
    stamp there was written, and writes the new stamp. Returns whether files were
    removed. Never raises for an unwritable folder."""
    cache = folder / "__pycache__"
    stamp = cache / _STAMP
    current = sources_hash(folder)
    try:
        if stamp.exists() and stamp.read_text() == current:
            return False
        stale = [path for where in (folder, *callers)
                 for pattern in ("*.nbi", "*.nbc")
                 for path in where.rglob(f"__pycache__/{pattern}")]
        for path in stale:
            path.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        # Atomic: processes that import the package together (a pool's workers) must
        # never read a half-written stamp, which would empty a cache another just filled.
        partial = cache / f"{_STAMP}.{os.getpid()}"
        partial.write_text(current)
        os.replace(partial, stamp)
        return bool(stale)
    except OSError:
        return False
