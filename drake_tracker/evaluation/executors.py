"""Where the evaluation's tasks run: the executor seam.

An :class:`Executor` has one job: ``map_unordered(function, tasks, on_progress)`` calls
``function(task, report)`` for every task somewhere (this process, local worker
processes, a Ray cluster) and yields an :class:`Outcome` per task as it finishes: the
payload ``function`` returned, or the error that stopped it. ``report(message)`` inside
a task reaches ``on_progress(task_name, message)`` in the driver. Executors neither
retry nor write files: the driver (``evaluation.run``) does both, the same for all.

Executors are context managers; leaving the context (normally, on an exception, on
Ctrl-C or SIGTERM turned into an exception) stops every worker they started.

* :class:`SerialExecutor`: in this process (tests, debugging).
* :class:`ProcessExecutor`: a local pool of spawned processes, one numba thread each.
* ``RayExecutor`` (``evaluation.ray_executor``): a Ray cluster, local or remote.
"""

from __future__ import annotations

import multiprocessing
import os
import queue as queue_module
import signal
import sys
import threading
import time
import traceback
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass

#: ``function(task, report) -> payload`` (a picklable callable for process executors).
TaskFunction = Callable
#: ``on_progress(task_name, message)``, called in the driver.
ProgressCallback = Callable[[str, str], None]


@dataclass
class Outcome:
    """What became of one task: its payload, or the error (text) that stopped it."""

    task: object
    payload: dict | None = None
    error: str | None = None


class Executor(ABC):
    """Runs tasks and yields their :class:`Outcome` as they finish (see module doc)."""

    #: The name ``--executor`` knows it by.
    name: str = ""
    #: Whether the workers see the driver's file system (then simulated runs are
    #: cached in ``OUT/runs``; otherwise only the returned payloads come back).
    shares_files: bool = True

    @abstractmethod
    def map_unordered(self, function: TaskFunction, tasks: Sequence,
                      on_progress: ProgressCallback | None = None) -> Iterator[Outcome]:
        """Yields one Outcome per task, in the order they finish."""

    def describe(self) -> str:
        """One line for the user: where the tasks run."""
        return self.name

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stops whatever the executor started (nothing by default)."""
        return None


def run_guarded(function: TaskFunction, task: object, report: Callable[[str], None]
                ) -> tuple[bool, object]:
    """``(True, payload)`` or ``(False, traceback text)``: a task's own error never
    escapes as an exception, so every executor reports it the same way."""
    try:
        return True, function(task, report)
    except Exception:  # noqa: BLE001 - any task error is reported, never raised
        return False, traceback.format_exc()


class SerialExecutor(Executor):
    """Runs the tasks one after another in this process."""

    name = "serial"

    def map_unordered(self, function: TaskFunction, tasks: Sequence,
                      on_progress: ProgressCallback | None = None) -> Iterator[Outcome]:
        """Runs the tasks one by one in this process, yielding each :class:`Outcome`;
        ``report`` calls ``on_progress`` directly."""
        for task in tasks:
            def report(message, _name=task.name):
                if on_progress:
                    on_progress(_name, message)

            ok, value = run_guarded(function, task, report)
            yield Outcome(task, value, None) if ok else Outcome(task, None, value)


def one_numba_thread() -> None:
    """Parallelism comes from the workers; numba threads on top of them would
    oversubscribe the cores (measured: 3x slower per image with 2 workers x 2 threads
    on 2 cores). The environment variable only before numba's import: numba re-reads
    it later and refuses a value other than its running pool's."""
    if "numba" not in sys.modules:
        os.environ["NUMBA_NUM_THREADS"] = "1"
    import numba

    numba.set_num_threads(1)


# --- the local process pool -------------------------------------------------------------

_progress_queue = None  # set in each pool worker by _init_pool_worker


def _watch_parent(parent_pid: int) -> None:
    # A worker whose driver is gone (killed with SIGKILL, say) exits instead of
    # finishing a task nobody will collect.
    while True:
        time.sleep(1.0)
        if os.getppid() != parent_pid:
            os._exit(1)


def _init_pool_worker(progress_queue, parent_pid: int) -> None:
    global _progress_queue
    # Ctrl-C reaches the whole process group: the driver stops the workers itself.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    one_numba_thread()
    _progress_queue = progress_queue
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True).start()


def _run_in_pool_worker(function, task) -> tuple[bool, object]:
    def report(message):
        try:
            _progress_queue.put_nowait((task.name, message))
        except Exception:  # noqa: BLE001 - progress is best effort
            pass

    return run_guarded(function, task, report)


def _drain(progress_queue, on_progress) -> None:
    while True:
        try:
            name, message = progress_queue.get_nowait()
        except (queue_module.Empty, OSError, ValueError):
            return
        if on_progress:
            on_progress(name, message)


class ProcessExecutor(Executor):
    """A local pool of ``workers`` processes (spawned, one numba thread each).

    Spawned workers import the calling script: a script that uses this executor keeps
    its work under ``if __name__ == "__main__":`` (the command line does).
    """

    name = "local"

    def __init__(self, workers: int):
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers

    def describe(self) -> str:
        """One line for the user: a local process pool and its number of workers."""
        return f"local process pool, {self.workers} worker(s)"

    def map_unordered(self, function: TaskFunction, tasks: Sequence,
                      on_progress: ProgressCallback | None = None) -> Iterator[Outcome]:
        """Runs the tasks on up to ``workers`` spawned processes and yields each
        :class:`Outcome` as it finishes (a worker that died gives its task an error). Progress
        messages come through a queue, drained at least every 0.5 s; an exception or an early
        stop ends the workers."""
        if not tasks:
            return
        context = multiprocessing.get_context("spawn")
        progress_queue = context.Queue()
        pool = ProcessPoolExecutor(max_workers=min(self.workers, len(tasks)),
                                   mp_context=context, initializer=_init_pool_worker,
                                   initargs=(progress_queue, os.getpid()))
        processes = []
        try:
            futures = {pool.submit(_run_in_pool_worker, function, task): task
                       for task in tasks}
            processes = list((getattr(pool, "_processes", None) or {}).values())
            pending = set(futures)
            while pending:
                done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                _drain(progress_queue, on_progress)
                for future in done:
                    task = futures[future]
                    try:
                        ok, value = future.result()
                    except Exception as e:  # noqa: BLE001 - a worker died (BrokenProcessPool)
                        ok, value = False, f"{type(e).__name__}: {e}"
                    yield Outcome(task, value, None) if ok else Outcome(task, None, value)
        except BaseException:
            # Ctrl-C, SIGTERM, or the consumer stopped early: end the workers now.
            processes = processes or list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            _terminate(processes)
            raise
        else:
            pool.shutdown(wait=True)
        finally:
            progress_queue.close()
            progress_queue.join_thread()


def _terminate(processes) -> None:
    for process in processes:
        if process.is_alive():
            process.terminate()
    deadline = time.monotonic() + 5.0
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.is_alive():
            process.kill()
            process.join(1.0)
