"""The evaluation's executors: retries and failure reports, the same results through
the local process pool and a local Ray instance, and stopping with SIGTERM."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

from drake_tracker.evaluation import ProcessExecutor, SerialExecutor, Task, evaluate, run_tasks


@dataclass(frozen=True)
class _Item:
    name: str


class _Flaky:
    """Fails ``a`` on its first call and ``b`` always; counts calls per name."""

    def __init__(self):
        self.calls: dict[str, int] = {}

    def __call__(self, item, report):
        self.calls[item.name] = self.calls.get(item.name, 0) + 1
        report(f"call {self.calls[item.name]}")
        if item.name == "b" or (item.name == "a" and self.calls["a"] == 1):
            raise RuntimeError(f"{item.name} broke")
        return {"name": item.name}


def test_a_failed_task_runs_once_more_then_is_reported_and_the_sweep_goes_on():
    function, results = _Flaky(), []
    items = [_Item("a"), _Item("b"), _Item("c")]
    failures = run_tasks(SerialExecutor(), function, items, results.append, progress=False)
    assert sorted(p["name"] for p in results) == ["a", "c"]
    assert function.calls == {"a": 2, "b": 2, "c": 1}
    assert list(failures) == ["b"] and "RuntimeError: b broke" in failures["b"]


def _fail_on_b(item, report):
    if item.name == "b":
        raise ValueError("no such sequence")
    return {"name": item.name, "pid": os.getpid(),
            "numba_threads": __import__("numba").get_num_threads()}


def test_the_process_pool_reports_errors_and_runs_one_numba_thread_per_worker():
    results = []
    failures = run_tasks(ProcessExecutor(2), _fail_on_b, [_Item("a"), _Item("b"), _Item("c")],
                         results.append, progress=False)
    assert sorted(p["name"] for p in results) == ["a", "c"]
    assert {p["numba_threads"] for p in results} == {1}
    assert os.getpid() not in {p["pid"] for p in results}
    assert "ValueError: no such sequence" in failures["b"]


# A tiny protocol: two seeds of a 1 s run, the encoders and the full tracker.
_TASKS = [Task("s-full-arm", "constant", seed, 1.0, 0.1, ("encoders_only", "full_fusion"))
          for seed in (0, 1)]


def test_ray_and_the_process_pool_give_identical_results_and_resume_each_other(tmp_path):
    """Both seeds through the local pool; then the pool's first result copied to a new
    folder (a run stopped after one task) and the rest finished through a local Ray
    instance that shares no files (results come back as payloads): same summary."""
    ray = pytest.importorskip("ray")
    from drake_tracker.evaluation.ray_executor import RayExecutor

    local, mixed = tmp_path / "local", tmp_path / "mixed"
    evaluate(_TASKS, local, ProcessExecutor(2), settle_s=0.5, progress=False)
    (mixed / "results").mkdir(parents=True)
    shutil.copy(local / "protocol.json", mixed)
    first, second = _TASKS[0].name, _TASKS[1].name
    for suffix in (".csv.gz", ".json"):
        shutil.copy(local / "results" / f"{first}{suffix}", mixed / "results")
    with RayExecutor(num_cpus=2, shares_files=False) as executor:
        evaluate(_TASKS, mixed, executor, settle_s=0.5, progress=False)
    assert not ray.is_initialized()  # the executor stopped the instance it started
    assert not (mixed / "runs").exists()  # nothing was written by the worker
    assert ((mixed / "results" / f"{second}.csv.gz").read_bytes()
            == (local / "results" / f"{second}.csv.gz").read_bytes())
    assert (mixed / "summary.csv").read_text() == (local / "summary.csv").read_text()
    for folder in (local, mixed):
        meta = json.loads((folder / "results" / f"{second}.json").read_text())
        assert meta["environment"]["numba_threads"] == 1


def _marked_processes(marker: str) -> list[int]:
    """Pids of the processes whose environment holds ``marker``."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and int(entry.name) != os.getpid():
            try:
                if marker.encode() in (entry / "environ").read_bytes():
                    pids.append(int(entry.name))
            except OSError:
                pass
    return pids


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs Linux /proc")
def test_sigterm_stops_the_workers_and_the_same_command_resumes(tmp_path):
    marker = f"DRAKE_TRACKER_TEST_MARKER={uuid.uuid4().hex}"
    env = {**os.environ, marker.split("=")[0]: marker.split("=")[1]}
    out = tmp_path / "out"
    command = [sys.executable, "-m", "drake_tracker.cli.main", "evaluate", "--quick",
               "--sequences", "s-full-arm", "--methods", "encoders_only", "--seeds", "1",
               "--duration", "1", "--settle-s", "0.5", "--workers", "2", "--out", str(out)]
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 240
        while not list((out / "results").glob("*.csv.gz")) and process.poll() is None:
            assert time.monotonic() < deadline, "no task finished in time"
            time.sleep(0.2)
        process.send_signal(signal.SIGTERM)
        output, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    finished = len(list((out / "results").glob("*.csv.gz")))
    if process.returncode != 0:  # stopped while tasks were running
        assert process.returncode == 143, output
        assert "the same command resumes" in output
    deadline = time.monotonic() + 15
    while _marked_processes(marker) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert _marked_processes(marker) == [], "worker processes survived SIGTERM"
    assert not list((out / "results").glob("*.tmp"))  # no half-written result
    resumed = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    counts = re.search(r"(\d+) tasks, (\d+) already done", resumed.stdout)
    assert counts and int(counts[2]) == finished >= 1, resumed.stdout
    assert len(list((out / "results").glob("*.csv.gz"))) == int(counts[1])
    assert (out / "boxplot_s-full-arm.png").exists()


def test_sigterm_stops_a_serial_evaluation_inside_a_task(tmp_path):
    """``--workers 1`` runs the tasks in the command's own process: SIGTERM lands inside
    a running task, and must stop the sweep there (exit 143), not count as the task's
    failure and let the sweep go on."""
    out = tmp_path / "out"
    command = [sys.executable, "-m", "drake_tracker.cli.main", "evaluate", "--quick",
               "--sequences", "s-full-arm", "--methods", "full_fusion", "--seeds", "3",
               "--duration", "2", "--settle-s", "0.5", "--workers", "1", "--out", str(out)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True)
    try:
        deadline = time.monotonic() + 240
        while not list((out / "results").glob("*.csv.gz")) and process.poll() is None:
            assert time.monotonic() < deadline, "no task finished in time"
            time.sleep(0.05)
        process.send_signal(signal.SIGTERM)  # the next task has started
        output, _ = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 143, output
    assert "the same command resumes" in output and "failed" not in output
    assert 1 <= len(list((out / "results").glob("*.csv.gz"))) < 3 * 3  # 3 seeds x 3 biases


def test_the_ray_executor_without_ray_says_how_to_install_it(tmp_path, monkeypatch):
    from drake_tracker.cli.main import main

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails
    out = tmp_path / "out"
    with pytest.raises(SystemExit, match=r"pip install 'drake_tracker\[cluster\]'"):
        main(["evaluate", "--quick", "--executor", "ray", "--out", str(out)])
    assert not out.exists()
