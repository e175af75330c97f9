"""The one place where drake_tracker chooses numba's threading layer.

Every module of the package that defines parallel kernels imports this module first,
so the choice is made before any parallel kernel runs (numba fixes its threading layer
at the first parallel launch).

Why: one image update makes about 60 parallel calls (one per CPF block and annealing
layer, ~35 particles each, about 0.5 ms of work on one thread). What a layer costs to
start and end such a call decides whether a second thread helps. Measured by
``drake-tracker bench`` on a 2-core Zen 4 VM (image updates/s, 1 thread -> 2 threads):

* ``omp`` (GNU OpenMP) with ``GOMP_SPINCOUNT`` 10,000 (:data:`DEFAULT_GOMP_SPINCOUNT`):
  31 -> 41-48. The workers spin through the gap between two blocks (tens of
  microseconds), then sleep. With OpenMP's default spin (300,000 iterations), idle
  workers steal the core that the serial part of the sweep, or the Drake Simulator,
  needs.
* ``workqueue`` (ships with numba): forced onto two threads, 31 -> 23. Its workers
  sleep on a condition variable and are woken per call, about 0.2 ms a call, so
  :class:`SerialOrParallel` keeps the sweep on one thread.

So the layer is chosen from :data:`LAYER_PRIORITY`: ``omp`` where numba can load it,
else ``workqueue``. GNU OpenMP is not fork-safe: numba terminates a child forked from a
process whose OpenMP threads have started at the child's first parallel launch, even
with one thread, and ``multiprocessing`` forks by default on Linux. The package's
kernels therefore run their serial compilations in such a child
(:func:`parallel_allowed`); the child computes the same numbers on one core.

The user's environment wins: ``NUMBA_THREADING_LAYER`` or
``NUMBA_THREADING_LAYER_PRIORITY`` (e.g. ``workqueue`` for a program whose own parallel
numba code runs in forked children), and ``GOMP_SPINCOUNT`` or ``OMP_WAIT_POLICY``.
Whatever the layer, :class:`SerialOrParallel` keeps a sweep on one thread while the
parallel run is the dearer. ``workqueue`` must not be entered from two Python threads
at once; the tracker runs its kernels from one thread.
"""

from __future__ import annotations

import os
import types
from collections import deque
from collections.abc import Callable

import numba

#: The layers numba tries, in order, when the user has named none.
LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
#: GNU OpenMP's spin (iterations) before an idle worker sleeps, unless the user set one.
DEFAULT_GOMP_SPINCOUNT = "10000"
#: Layers after whose start a forked child must not launch a parallel kernel.
FORK_UNSAFE_LAYERS = frozenset({"omp", "tbb"})


def configure_threading_layer() -> str:
    """Lets numba pick from :data:`LAYER_PRIORITY` unless the user's environment names a
    layer or a priority, and bounds OpenMP's spin (:data:`DEFAULT_GOMP_SPINCOUNT`) unless
    the environment sets one. Returns the configured layer name, ``default`` meaning
    the first of the priority that loads (numba loads it at its first parallel launch).
    Harmless once a layer is loaded: numba then keeps it."""
    requested = os.environ.get("NUMBA_THREADING_LAYER", "").strip()
    if requested in ("", "default", "omp") and not (os.environ.get("GOMP_SPINCOUNT")
                                                   or os.environ.get("OMP_WAIT_POLICY")):
        os.environ["GOMP_SPINCOUNT"] = DEFAULT_GOMP_SPINCOUNT
    if requested:
        return requested
    if not os.environ.get("NUMBA_THREADING_LAYER_PRIORITY", "").strip():
        numba.config.THREADING_LAYER_PRIORITY = list(LAYER_PRIORITY)
    return str(numba.config.THREADING_LAYER)


configure_threading_layer()

_forked_after_unsafe_start = False

#: Calls recorded in this process, per compilation (False: serial, True: parallel), by
#: every :class:`SerialOrParallel`: loading the code and starting the threads happen
#: once per process, so only a process's first calls are warm-up calls.
_calls_in_process = {False: 0, True: 0}

#: The latest costs per item of each compilation measured in this process (the window
#: of the policy that last recorded one): a new :class:`SerialOrParallel` (a new
#: tracker's renderer) starts from them.
_latest_costs: dict[bool, tuple[float, ...]] = {False: (), True: ()}


def _after_fork_in_child() -> None:
    """In a forked child: remembers whether the parent had started a fork-unsafe layer
    (and counts its own warm-up calls afresh: its threads are its own)."""
    global _forked_after_unsafe_start
    from numba.np.ufunc import parallel
    _calls_in_process.update({False: 0, True: 0})
    _latest_costs.update({False: (), True: ()})
    if parallel._is_initialized and numba.threading_layer() in FORK_UNSAFE_LAYERS:
        _forked_after_unsafe_start = True


os.register_at_fork(after_in_child=_after_fork_in_child)


def parallel_allowed() -> bool:
    """Whether the package may launch a parallel kernel here: numba has more than one
    thread, and this process is not a fork of one whose fork-unsafe layer (GNU OpenMP)
    had started (there the kernels run their serial compilations)."""
    return not _forked_after_unsafe_start and numba.get_num_threads() > 1


def pick_kernel(serial: Callable, parallel: Callable) -> Callable:
    """``parallel`` where :func:`parallel_allowed`, else ``serial``: the two
    compilations of :func:`serial_and_parallel`."""
    return parallel if parallel_allowed() else serial


class SerialOrParallel:
    """Chooses, call by call, between a kernel's serial and parallel compilations by their
    measured cost per item, so that more threads never make the work slower.

    Even a non-spinning layer must wake its workers at each parallel call; on a loaded
    machine that wake-up can cost more than the work of a CPF block (measured: 2 threads
    3x slower than 1 at a load average of 25 on 2 cores). The parallel version is used
    while it is the cheaper of the two, each's cost the least seconds per item of its
    latest ``window`` calls: a call can only be slowed by the machine (another process,
    a preempted worker), so the least is the robust figure. (With an exponential average
    instead, one preempted parallel sweep of 17.6 against 9-13 µs per evaluation kept the
    bench's two threads on the serial kernel for 16 updates, and two threads measured
    1.24x one thread in one bench run of five, 1.59-1.62x in the others.)
    every ``probe_interval``-th call tries the other one, so a change of load is followed.
    A probe that finds the other one still dearer doubles the interval (up to
    ``max_probe_every``); one that finds it cheaper, or a change of the choice, sets it
    back to ``probe_every``. (Measured: probing every 64th sweep made 2 threads 0.6-1 %
    slower than 1 on this machine, where the parallel sweep is the dearer.)
    With one numba thread, or in a forked child where a parallel launch is unsafe
    (:func:`parallel_allowed`), the serial version is always used.
    """

    def __init__(self, probe_every: int = 64, window: int = 5,
                 warmup_calls: int = 1, max_probe_every: int = 4096):
        """``warmup_calls``: the process's first calls of each compilation are not
        measured (they include loading the code and starting the threads: milliseconds,
        which made the parallel kernel look several times dearer than it is, and kept the
        policy on the serial one for hundreds of calls). They are counted over the
        process, not per policy: each tracker's renderer has its own policy, and with
        warm-up calls of its own, a new tracker in a warmed-up process ran its first
        search's four sweeps serial, serial, parallel unmeasured, parallel; the search
        took 121-195 ms against 52-84 ms for the next two on two threads.

        A policy starts from the window of costs the process last measured (any
        policy's), and measures serial first only in a process that measured nothing: a
        new tracker in a warmed-up process ran its first sweep serial to learn what the
        process already knew, and its first search took 81-103 ms against 44-75 ms for
        the next one (the demo's sensors held to real time, two threads, Zen 5), beyond a
        30 Hz camera's 80 ms deadline. The inherited costs stay in the window until its
        own calls push them out: inheriting the least costs alone, one parallel sweep
        slowed at a run's start (12 µs per evaluation against 4-6) flipped the new policy
        to serial for 64 sweeps. The inherited costs may come from another workload (a
        robot with more triangles, another image size): a choice they make wrongly lasts
        until ``window`` of this policy's own calls of that compilation replace them."""
        self.probe_every = int(probe_every)
        self.max_probe_every = max(int(max_probe_every), self.probe_every)
        self.probe_interval = self.probe_every
        self.window = max(1, int(window))
        self._recent: dict[bool, deque[float]] = {
            b: deque(_latest_costs[b], maxlen=self.window) for b in (False, True)}
        self.warmup_calls = int(warmup_calls)
        self.cost_per_item: dict[bool, float | None] = {
            b: min(self._recent[b]) if self._recent[b] else None for b in (False, True)}
        self._calls = 0

    def use_parallel(self) -> bool:
        """Whether the next call should run the parallel compilation."""
        if not parallel_allowed():
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
        _calls_in_process[parallel] += 1
        if _calls_in_process[parallel] <= self.warmup_calls:
            return
        cost = seconds / max(1, items)
        before = self._parallel_is_faster()
        self._recent[parallel].append(cost)
        self.cost_per_item[parallel] = min(self._recent[parallel])
        _latest_costs[parallel] = tuple(self._recent[parallel])
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
