"""The evaluation's tasks on a Ray cluster (the optional ``cluster`` extra).

``RayExecutor()`` starts a local Ray instance for the run and stops it after;
``RayExecutor(address="HOST:6379")`` (or ``"auto"``) joins a running cluster started
with ``ray start --head`` and ``ray start --address=HOST:6379`` on the workers. Every
node needs drake_tracker installed (``pip install drake_tracker[cluster]``).

Each task runs as a Ray task with one CPU and one numba thread (``NUMBA_NUM_THREADS=1``
in the job's runtime environment). The task function returns its payload (the per-task
result), which Ray sends back to the driver; the driver writes it. Nothing is written
on the workers unless they share the driver's file system (a local instance does: then
simulated runs are cached in ``OUT/runs`` as with the process pool). Task progress
messages come back through a ``ray.util.queue.Queue``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

from drake_tracker.evaluation.executors import (
    Executor,
    Outcome,
    ProgressCallback,
    TaskFunction,
    one_numba_thread,
    run_guarded,
)

if TYPE_CHECKING:
    from types import ModuleType

MISSING_RAY = ("the ray executor needs Ray: pip install 'drake_tracker[cluster]' "
               "(or pip install 'ray[default]')")


def import_ray() -> ModuleType:
    """``ray``, or an ImportError with the one line that says how to install it."""
    try:
        import ray
    except ImportError:
        raise ImportError(MISSING_RAY) from None
    return ray


def _run_in_ray_worker(function, task, progress_queue) -> tuple[bool, object]:
    one_numba_thread()

    def report(message):
        # Fire and forget: a blocking put (a ray.get inside the task) would lend the
        # task's CPU to another task meanwhile, and oversubscribe the node.
        try:
            progress_queue.actor.put_nowait.remote((task.name, message))
        except Exception:  # noqa: BLE001 - progress is best effort
            pass

    return run_guarded(function, task, report)


class RayExecutor(Executor):
    """Tasks as Ray tasks; a local instance (``address=None``) or an existing cluster."""

    name = "ray"

    def __init__(self, address: str | None = None, num_cpus: int | None = None,
                 shares_files: bool | None = None):
        self.address = address
        self.num_cpus = num_cpus
        #: A local instance shares the driver's files; a remote cluster is assumed not to.
        self.shares_files = address is None if shares_files is None else shares_files
        self._ray = None
        self._started_here = False
        import_ray()  # fail here, with the install line, before any work starts

    def describe(self) -> str:
        """One line for the user: local instance or cluster address, and its CPU count ("?"
        before the executor is entered)."""
        ray = self._ray
        cpus = int(ray.cluster_resources().get("CPU", 0)) if ray else "?"
        where = "a local Ray instance" if self.address is None else f"Ray at {self.address}"
        return f"{where}, {cpus} CPU(s), one task per CPU"

    def __enter__(self) -> RayExecutor:
        ray = import_ray()
        self._ray = ray
        if ray.is_initialized():
            return self  # the caller's own Ray session (tests, notebooks): keep it
        runtime_env = {"env_vars": {"NUMBA_NUM_THREADS": "1"}}
        if self.address is None:
            ray.init(num_cpus=self.num_cpus, include_dashboard=False, log_to_driver=False,
                     logging_level=logging.WARNING, runtime_env=runtime_env)
        else:
            ray.init(address=self.address, log_to_driver=False,
                     logging_level=logging.WARNING, runtime_env=runtime_env)
        self._started_here = True
        return self

    def close(self) -> None:
        """Shuts Ray down if this executor initialised it (a local instance stops, a cluster
        keeps running); a Ray session the caller started is left alone."""
        if self._ray is not None and self._started_here:
            self._ray.shutdown()  # stops a local instance's processes; leaves a cluster
            self._started_here = False

    def map_unordered(self, function: TaskFunction, tasks: Sequence,
                      on_progress: ProgressCallback | None = None) -> Iterator[Outcome]:
        """Runs each task as a one-CPU Ray task without retries (entering the executor first
        if needed) and yields each :class:`Outcome` as it finishes; progress comes back through
        a Ray queue. An exception or an early stop cancels the pending tasks."""
        if not tasks:
            return
        if self._ray is None:
            self.__enter__()
        ray = self._ray
        from ray.util.queue import Queue

        progress_queue = Queue()
        remote = ray.remote(num_cpus=1, max_retries=0)(_run_in_ray_worker)
        function_ref = ray.put(function)
        refs = {remote.remote(function_ref, task, progress_queue): task for task in tasks}
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1, timeout=0.5)
                self._drain(progress_queue, on_progress)
                for ref in done:
                    try:
                        ok, value = ray.get(ref)
                    except Exception as e:  # noqa: BLE001 - the worker died or Ray failed
                        ok, value = False, f"{type(e).__name__}: {e}"
                    task = refs[ref]
                    yield Outcome(task, value, None) if ok else Outcome(task, None, value)
        except BaseException:
            for ref in pending:  # Ctrl-C, SIGTERM or an early stop: kill running tasks
                ray.cancel(ref, force=True)
            raise
        finally:
            progress_queue.shutdown(force=True)

    @staticmethod
    def _drain(progress_queue, on_progress) -> None:
        try:
            messages = progress_queue.get_nowait_batch(progress_queue.qsize())
        except Exception:  # noqa: BLE001 - progress is best effort
            return
        if on_progress:
            for name, message in messages:
                on_progress(name, message)
