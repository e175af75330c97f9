"""The executor that ``drake-tracker evaluate --executor NAME`` stands for."""

from drake_tracker.evaluation.executors import Executor, ProcessExecutor, SerialExecutor
from drake_tracker.evaluation.ray_executor import RayExecutor


def make_executor(name: str, workers: int = 2, address: str | None = None) -> Executor:
    """The executor ``--executor NAME`` stands for (``local`` with 1 worker: serial)."""
    if name == "local":
        return SerialExecutor() if workers <= 1 else ProcessExecutor(workers)
    if name == "ray":
        return RayExecutor(address=address, num_cpus=workers if address is None else None)
    raise ValueError(f"unknown executor '{name}'; known: local, ray")
