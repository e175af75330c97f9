"""The one place where drake_tracker chooses numba's threading layer.

Every module of the package that defines ``parallel=True`` kernels imports this module
first, so the choice is made before any parallel kernel runs (numba fixes its threading
layer at the first parallel launch).

Why: one image update makes about 60 small parallel calls (one per CPF block and
annealing layer, ~35 particles each). Numba's default layer on Linux is OpenMP, whose
worker threads spin-wait at every barrier; on a machine where the cores are shared, two
threads made an image update 3-5x *slower* than one. The ``workqueue`` layer ships with
numba (no extra dependency) and its workers sleep instead of spinning, so a second thread
never costs more than it brings (measured by ``drake-tracker bench``, 1 vs 2 threads).

Its limit: workqueue must not be entered from two Python threads at once. The tracker
runs its kernels from one thread (the Drake Simulator's, or the offline loop's); parallel
evaluations use processes. A user who needs thread-safe concurrent calls can choose
another layer with the environment variable ``NUMBA_THREADING_LAYER`` (e.g. ``tbb`` after
``pip install tbb``, or ``omp`` with ``OMP_WAIT_POLICY=PASSIVE``), which always wins over
this default.
"""

from __future__ import annotations

import os
import types
from collections.abc import Callable

import numba

#: The layer chosen when the user has not set ``NUMBA_THREADING_LAYER``.
DEFAULT_THREADING_LAYER = "workqueue"


def configure_threading_layer() -> str:
    """Selects :data:`DEFAULT_THREADING_LAYER` unless the user's environment names a layer.

    Returns the configured layer name (what numba will load at its first parallel
    launch). Harmless once a layer is loaded: numba then keeps the one it has.
    """
    requested = os.environ.get("NUMBA_THREADING_LAYER", "").strip()
    if requested:
        return requested
    if numba.config.THREADING_LAYER == "default":
        numba.config.THREADING_LAYER = DEFAULT_THREADING_LAYER
    return str(numba.config.THREADING_LAYER)


configure_threading_layer()


class SerialOrParallel:
    """Chooses, call by call, between a kernel's serial and parallel compilations by their
    measured cost per item, so that more threads never make the work slower.

    Even a non-spinning layer must wake its workers at each parallel call; on a loaded
    machine that wake-up can cost more than the work of a CPF block (measured: 2 threads
    3x slower than 1 at a load average of 25 on 2 cores). The parallel version is used
    while it is the cheaper of the two (exponential moving averages of seconds per item);
    every ``probe_interval``-th call tries the other one, so a change of load is followed.
    A probe that finds the other one still dearer doubles the interval (up to
    ``max_probe_every``); one that finds it cheaper, or a change of the choice, sets it
    back to ``probe_every``. (Measured: probing every 64th sweep made 2 threads 0.6-1 %
    slower than 1 on this machine, where the parallel sweep is the dearer.)
    With one numba thread the serial version is always used.
    """

    def __init__(self, probe_every: int = 64, smoothing: float = 0.3,
                 warmup_calls: int = 1, max_probe_every: int = 4096):
        """``warmup_calls``: the first calls of each compilation are not measured (they
        include loading the code and starting the threads: milliseconds, which made the
        parallel kernel look several times dearer than it is, and kept the policy on the
        serial one for hundreds of calls)."""
        self.probe_every = int(probe_every)
        self.max_probe_every = max(int(max_probe_every), self.probe_every)
        self.probe_interval = self.probe_every
        self.smoothing = float(smoothing)
        self.warmup_calls = int(warmup_calls)
        self.cost_per_item: dict[bool, float | None] = {False: None, True: None}
        self._calls = 0
        self._seen = {False: 0, True: 0}

    def use_parallel(self) -> bool:
        """Whether the next call should run the parallel compilation."""
        if numba.get_num_threads() == 1:
            return False
        self._calls += 1
        serial, parallel = self.cost_per_item[False], self.cost_per_item[True]
        if serial is None:
            return False  # measure serial first, then parallel
        if parallel is None:
            return True
        faster = parallel < serial
        if self._calls >= self.probe_interval:
            self._calls = 0
            return not faster
        return faster

    def record(self, parallel: bool, seconds: float, items: int) -> None:
        """Records a call's wall time for ``items`` items (ignored while warming up)."""
        self._seen[parallel] += 1
        if self._seen[parallel] <= self.warmup_calls:
            return
        cost = seconds / max(1, items)
        before = self._parallel_is_faster()
        old = self.cost_per_item[parallel]
        self.cost_per_item[parallel] = cost if old is None else (
            (1.0 - self.smoothing) * old + self.smoothing * cost)
        after = self._parallel_is_faster()
        if before is None or after is None:
            return
        if before != after:  # a probe found the other cheaper, or the choice got dearer
            self.probe_interval = self.probe_every
        elif parallel != before:  # a probe, and the other one is still the dearer
            self.probe_interval = min(2 * self.probe_interval, self.max_probe_every)

    def _parallel_is_faster(self) -> bool | None:
        serial, parallel = self.cost_per_item[False], self.cost_per_item[True]
        return None if serial is None or parallel is None else parallel < serial


def serial_and_parallel(function: Callable, **options: object) -> tuple[Callable, Callable]:
    """``function`` compiled twice with ``cache=True``: serially, and with
    ``parallel=True`` (its ``prange`` loops over threads).

    Numba's on-disk cache keys a compiled function by its qualified name, source line and
    argument types, not by its compile options (numba issue 6845): compiled twice under
    one name, the second compilation loads the first one's machine code from the cache,
    and the "parallel" kernel runs serially. The parallel one is therefore compiled from
    a copy of the function under another qualified name, which has cache files of its own.
    """
    renamed = types.FunctionType(function.__code__, function.__globals__,
                                 function.__name__ + "_parallel", function.__defaults__,
                                 function.__closure__)
    renamed.__qualname__ = function.__qualname__ + "_parallel"
    renamed.__doc__ = function.__doc__
    renamed.__module__ = function.__module__
    return (numba.njit(cache=True, **options)(function),
            numba.njit(cache=True, parallel=True, **options)(renamed))
