"""``drake-tracker evaluate``: the paper's protocol (README, "Evaluation") on the simulated suite.

Work is split into tasks, one per (sequence, bias variant, seed) (``tasks``): a task
simulates its run, replays it through every method, and returns its errors sampled at
regular times. An executor runs the tasks (``executors``: in this process, a local
process pool, or Ray in ``ray_executor``); the driver (``run``) writes each returned
result atomically as ``results/<task>.csv`` (``results``), so a stopped evaluation
resumes where it stopped, on either executor, and retries a failed task once.

Outputs in ``--out DIR``: ``errors.csv`` (all samples), ``summary.csv`` (``summary``:
percentiles over all seeds, the median over seeds and the worst seed), ``summary.txt``,
``failures.json``, ``protocol.json`` (settings, package versions, CPU, threads), box
plots and time series (``plots``).
"""

from drake_tracker.evaluation.executor_choice import make_executor
from drake_tracker.evaluation.executors import (
    Executor,
    Outcome,
    ProcessExecutor,
    SerialExecutor,
)
from drake_tracker.evaluation.plots import plot_results
from drake_tracker.evaluation.results import ResultStore
from drake_tracker.evaluation.run import evaluate, run_evaluate, run_tasks
from drake_tracker.evaluation.summary import settled, summarize, write_summary
from drake_tracker.evaluation.tasks import (
    QUICK_SEQUENCES,
    SETTLE_S,
    Task,
    compute_task,
    evaluate_run,
    make_tasks,
    task_base_params,
    task_name,
)

__all__ = [
    "QUICK_SEQUENCES", "SETTLE_S", "Executor", "Outcome", "ProcessExecutor", "ResultStore",
    "SerialExecutor", "Task", "compute_task", "evaluate", "evaluate_run", "make_executor",
    "make_tasks", "plot_results", "run_evaluate", "run_tasks", "settled", "summarize",
    "task_base_params", "task_name", "write_summary",
]
