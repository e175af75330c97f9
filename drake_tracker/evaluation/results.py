"""The evaluation's folder: per-task results, failures and ``protocol.json``.

Only the driver writes here. A task's payload becomes ``results/<task>.json`` (its
environment and wall times) and then ``results/<task>.csv.gz`` (its errors, gzip with
no time stamp, so the same errors give the same bytes), each written to a temporary file
and renamed, so a result file is always complete. A task counts as done when its errors
file exists: a stopped evaluation resumes with the others, whichever executor ran the
finished ones. Compressed, the full protocol's 360 results take about 13 MB instead of
75, small enough to commit, so a protocol run in slices on machines that do not keep
their files resumes from a clone. Plain ``results/<task>.csv`` files (older folders)
are read too.
"""

from __future__ import annotations

import gzip
import json
import os
from pathlib import Path

from drake_tracker.evaluation.summary import read_errors_csv
from drake_tracker.evaluation.tasks import Task, environment

_ERRORS_SUFFIXES = (".csv.gz", ".csv")  # written, then read as well (older folders)
#: A payload's other tables, each in ``results/<kind>/<task>.csv.gz``: each camera's
#: frame against the truth, and the health just after each image.
_SIDE_FILES = ("cameras", "images")


def _write_atomic(path: Path, data: str | bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    if isinstance(data, bytes):
        tmp.write_bytes(data)
    else:
        tmp.write_text(data)
    os.replace(tmp, path)


class ResultStore:
    """Reads and writes the files of one evaluation folder."""

    def __init__(self, out_dir: Path):
        self.out_dir = Path(out_dir)
        self.results_dir = self.out_dir / "results"

    def result_path(self, name: str) -> Path:
        """``results/<name>.csv.gz``, the errors file written for task ``name``."""
        return self.results_dir / f"{name}{_ERRORS_SUFFIXES[0]}"

    def stored_errors(self, name: str) -> Path | None:
        """The errors file of task ``name`` (compressed, or an older plain CSV), if any."""
        for suffix in _ERRORS_SUFFIXES:
            path = self.results_dir / f"{name}{suffix}"
            if path.exists():
                return path
        return None

    def read_errors(self, name: str) -> list[dict]:
        """The stored error samples of task ``name`` (rows of its errors CSV); raises
        FileNotFoundError naming the folder when the task has none."""
        path = self.stored_errors(name)
        if path is None:
            raise FileNotFoundError(f"no stored errors of task '{name}' in "
                                    f"{self.results_dir}")
        return read_errors_csv(path)

    def is_done(self, task: Task) -> bool:
        """Whether ``task``'s errors file exists (a resumed evaluation skips it)."""
        return self.stored_errors(task.name) is not None

    def write(self, payload: dict) -> None:
        """Writes a task's payload (from :func:`~.tasks.compute_task`), its errors CSV
        last; each camera's frame against the truth (``cameras_csv``, if any) goes to
        ``results/cameras/<name>.csv.gz``, the health after each image (``images_csv``)
        to ``results/images/<name>.csv.gz``."""
        name = payload["name"]
        meta = {k: v for k, v in payload.items() if not k.endswith("csv")}
        _write_atomic(self.results_dir / f"{name}.json", json.dumps(meta, indent=1))
        for kind in _SIDE_FILES:
            if payload.get(f"{kind}_csv"):
                _write_atomic(self._side_path(kind, name), gzip.compress(
                    payload[f"{kind}_csv"].encode(), compresslevel=9, mtime=0))
        _write_atomic(self.result_path(name),
                      gzip.compress(payload["csv"].encode(), compresslevel=9, mtime=0))

    def load_rows(self, tasks: list[Task] | None = None) -> list[dict]:
        """Every stored error sample (of ``tasks`` only, if given), in task-name order."""
        names = {path.name.removesuffix(suffix) for suffix in _ERRORS_SUFFIXES
                 for path in self.results_dir.glob(f"*{suffix}")}
        if tasks is not None:
            names &= {t.name for t in tasks}
        rows = []
        for name in sorted(names):
            rows.extend(self.read_errors(name))
        return rows

    def _side_path(self, kind: str, name: str) -> Path:
        return self.results_dir / kind / f"{name}{_ERRORS_SUFFIXES[0]}"

    def _load_side_rows(self, kind: str, tasks: list[Task]) -> list[dict]:
        rows = []
        for task in sorted(tasks, key=lambda t: t.name):
            path = self._side_path(kind, task.name)
            if path.exists() and self.is_done(task):
                rows.extend(read_errors_csv(path))
        return rows

    def load_camera_rows(self, tasks: list[Task]) -> list[dict]:
        """The stored per-camera samples (``camera_frames.CAMERA_COLUMNS``) of the done
        ``tasks`` that have them (results stored before they were written have none)."""
        return self._load_side_rows("cameras", tasks)

    def load_image_rows(self, tasks: list[Task]) -> list[dict]:
        """The stored per-image health rows (``health_calibration.IMAGE_COLUMNS``) of the
        done ``tasks`` that have them (results stored before they were written have
        none)."""
        return self._load_side_rows("images", tasks)

    def load_metas(self, tasks: list[Task]) -> list[dict]:
        """The stored environments and wall times of ``tasks`` (older results have none)."""
        metas = []
        for task in tasks:
            path = self.results_dir / f"{task.name}.json"
            if path.exists() and self.is_done(task):
                metas.append(json.loads(path.read_text()))
        return metas

    def write_failures(self, failures: dict[str, str]) -> Path:
        """``failures.json``: {task name: error text} of the tasks that failed twice
        in the last run (empty when all succeeded)."""
        path = self.out_dir / "failures.json"
        _write_atomic(path, json.dumps(failures, indent=1))
        return path


def protocol_settings(tasks: list[Task]) -> list:
    """What must match for results to share a folder (task files are named by
    sequence, bias and seed only): duration, image interval, methods, parameters."""
    return sorted({json.dumps([t.duration_s, t.min_image_interval_s, list(t.methods),
                               t.params_yaml]) for t in tasks})


def check_same_protocol(tasks: list[Task], out_dir: Path) -> None:
    """Refuses (ValueError) to mix results of different protocols in one folder; writes
    ``protocol.json`` with the settings and the driver's environment on first use."""
    path = Path(out_dir) / "protocol.json"
    settings = protocol_settings(tasks)
    if path.exists():
        stored = json.loads(path.read_text())
        stored_settings = stored["settings"] if isinstance(stored, dict) else stored
        if stored_settings != settings:
            raise ValueError(f"{out_dir} holds results of another protocol (duration, image "
                             f"interval, methods or parameters: {stored_settings}); use a new "
                             f"--out folder")
    else:
        _write_atomic(path, json.dumps({"settings": settings, "driver": environment(),
                                        "task_environments": []}, indent=1))


def record_environments(out_dir: Path, metas: list[dict]) -> list[dict]:
    """Adds the distinct environments the finished tasks ran in (package versions, CPU,
    numba threads), with their task counts, to ``protocol.json``; returns them."""
    path = Path(out_dir) / "protocol.json"
    stored = json.loads(path.read_text())
    if not isinstance(stored, dict):
        stored = {"settings": stored}
    counts: dict[str, int] = {}
    for meta in metas:
        if "environment" in meta:
            key = json.dumps(meta["environment"], sort_keys=True)
            counts[key] = counts.get(key, 0) + 1
    environments = [{**json.loads(k), "tasks": n} for k, n in sorted(counts.items())]
    stored["task_environments"] = environments
    _write_atomic(path, json.dumps(stored, indent=1))
    return environments
