"""The thread that runs image updates while a Drake Simulator goes on.

The paper runs its two filters in parallel, at their own rates: an image's update takes
tens of milliseconds, and the joint filter does not wait for it. In a Diagram the
:class:`~drake_tracker.systems.cpf_system.CpfImageUpdateSystem` models that with
``image.update_latency_s``: it hands the update to this worker when the image arrives
and applies the result that much simulated time later (waiting for it there if it is
not done). The result does not depend on how fast the worker was, so a simulation stays
deterministic, and on a machine with two cores the update overlaps the rest of the
simulation.

One worker thread serves every tracker of the process, so the compiled kernels are
never entered from two threads at once (numba's ``workqueue`` layer does not allow
it). Under a layer that allows it (GNU OpenMP, the default:
``core/jit/numba_threading.py``) the worker may use all numba's threads, and each
kernel's serial-or-parallel policy decides by measured cost whether the second core is
better spent on the update or left to the Simulator. Measured with the bench's tracker
alone on the demo's recorded sensors (6 s, Zen 4 VM, two rounds): real-time factor
1.56-1.57 on one numba thread, 1.84-1.95 on two; the demo, whose Simulator thread also
renders the camera, 1.17-1.19 against 1.13-1.17 (the policy keeps it serial there).
"""

from __future__ import annotations

import atexit
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numba

_lock = threading.Lock()
_executor: ThreadPoolExecutor | None = None


def _worker_numba_threads() -> None:
    # numba's thread count is per calling thread. workqueue must not be entered from two
    # threads at once, and the Simulator's thread may run a kernel too: one thread there.
    numba.get_num_threads()  # starts the layer, so that it can be named
    one = numba.threading_layer() == "workqueue"
    numba.set_num_threads(1 if one else numba.config.NUMBA_NUM_THREADS)


def _worker() -> ThreadPoolExecutor:
    global _executor
    with _lock:
        if _executor is None:
            _executor = ThreadPoolExecutor(max_workers=1, initializer=_worker_numba_threads,
                                           thread_name_prefix="drake_tracker_image_update")
            atexit.register(_executor.shutdown, wait=False, cancel_futures=True)
        return _executor


def _forget_in_child() -> None:
    # A forked child has the executor but not its thread: it would queue work forever.
    global _executor, _lock
    _executor, _lock = None, threading.Lock()


os.register_at_fork(after_in_child=_forget_in_child)


def submit_image_update(function: Callable[..., Any], *args: Any) -> Future:
    """Runs ``function(*args)`` on the image-update thread; its Future."""
    return _worker().submit(function, *args)


@dataclass
class DeadlineWaits:
    """Whether each update on the worker was done at its deadline, and how long the
    Simulator waited for the late ones (wall-clock s). A machine keeps up with the
    tracker at real time only if updates are rarely late. A diagnostic of the system,
    over all its Contexts since it was built: it is not in any Context, and it changes
    no estimate."""

    on_time: int = 0
    late: int = 0
    waited_s: float = 0.0
    #: Of the late ones, the searches (updates started before the arm was acquired:
    #: ``image.acquisition_num_particles`` per block, three times a tracked update's
    #: evaluations by default), which a deadline set for a tracked update does not fit.
    late_searches: int = 0

    def join(self, outcome: Future, search: bool = False) -> Any:
        """``outcome.result()`` (raising what the update raised), counted; ``search``:
        the update was started as a search."""
        if outcome.done():
            self.on_time += 1
            return outcome.result()
        start = time.perf_counter()
        try:
            return outcome.result()
        finally:
            self.late += 1
            self.late_searches += bool(search)
            self.waited_s += time.perf_counter() - start
