"""Functional core of the tracker: plain numpy/numba code, no Diagram needed."""

from drake_tracker.core.jit.kernel_cache import clear_stale_kernel_cache

clear_stale_kernel_cache()
