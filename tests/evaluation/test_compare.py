"""``drake-tracker compare`` (``evaluation/compare.py``) on errors.csv files written here,
whose run medians are known by construction."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from drake_tracker.cli.main import main
from drake_tracker.evaluation.compare import compare, format_comparison, run_medians

COLUMNS = ["sequence", "bias", "method", "seed", "time_s", "translation_mm",
           "rotation_deg", "health"]


def write_errors(folder, runs, method="full_fusion"):
    """``runs``: {(sequence, bias, seed): samples}, each sampled at t = 0, 1, 2, ... s."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "errors.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for (sequence, bias, seed), samples in runs.items():
            for t, e in enumerate(samples):
                w.writerow([sequence, bias, method, seed, f"{t:.4f}", e, 0.1, "tracking"])
                w.writerow([sequence, bias, "encoders_only", seed, f"{t:.4f}", 999.0, 9.0,
                            "uncertain"])
    return folder


def settled_run(median, before=1000.0):
    """Samples whose median from t = 5 s on is ``median``; large ones before 5 s."""
    return [before] * 5 + [median - 1.0, median, median + 1.0]


def test_run_medians_keep_the_settled_samples_of_the_method(tmp_path):
    folder = write_errors(tmp_path / "a", {("s", "b", 0): settled_run(4.0),
                                           ("s", "b", 1): settled_run(6.0),
                                           ("s", "c", 0): [np.nan] * 8})
    assert run_medians([folder], "full_fusion", 5.0) == {("s", "b"): [4.0, 6.0]}
    assert run_medians([folder], "full_fusion", 0.0)[("s", "b")] == [1000.0, 1000.0]
    with pytest.raises(ValueError, match="vision_only"):
        run_medians([folder], "vision_only", 5.0)
    with pytest.raises(ValueError, match="no errors.csv"):
        run_medians([tmp_path], "full_fusion", 5.0)


def test_the_pooled_ratio_and_the_cells_verdicts(tmp_path):
    medians = {("s", "b"): [2.0, 3.0, 5.0], ("t", "b"): [10.0, 20.0, 40.0]}
    runs = {(s, b, k): settled_run(m) for (s, b), ms in medians.items()
            for k, m in enumerate(ms)}
    before = write_errors(tmp_path / "before", runs)
    # Every run 1.2 times as far off: the ratio is 1.2 whatever the bootstrap draws.
    scaled = write_errors(tmp_path / "scaled", {k: settled_run(1.2 * float(np.median(
        v[5:]))) for k, v in runs.items()})
    c = compare([before], [scaled])
    assert math.isclose(c.ratio, 1.2, rel_tol=1e-12)
    assert c.ratio_interval[0] <= 1.2 <= c.ratio_interval[1]
    by_cell = {(x.sequence, x.bias): x for x in c.cells}
    # s/b: median 3 -> 3.6, worst 5 -> 6.0: within 10 % + 0.5 mm (3.8, 6.0), not worse.
    assert by_cell["s", "b"].median_mm == (3.0, pytest.approx(3.6))
    assert not by_cell["s", "b"].worse and not by_cell["s", "b"].better
    # t/b: 20 -> 24 (> 22.5) and 40 -> 48 (> 44.5): worse.
    assert by_cell["t", "b"].worse and not by_cell["t", "b"].better
    reverse = compare([scaled], [before])
    assert math.isclose(reverse.ratio, 1 / 1.2, rel_tol=1e-12)
    assert {(x.sequence, x.better) for x in reverse.cells} == {("s", False), ("t", True)}


def test_pooled_folders_add_runs_and_cells_on_one_side_are_named(tmp_path):
    a = write_errors(tmp_path / "a", {("s", "b", 0): settled_run(2.0),
                                      ("only", "before", 0): settled_run(2.0)})
    a2 = write_errors(tmp_path / "a2", {("s", "b", 0): settled_run(4.0)})
    b = write_errors(tmp_path / "b", {("s", "b", 0): settled_run(3.0),
                                      ("only", "after", 0): settled_run(2.0)})
    c = compare([a, a2], [b])
    assert c.cells[0].runs == (2, 1) and c.cells[0].worst_mm == (4.0, 3.0)
    assert c.only_before == [("only", "before")] and c.only_after == [("only", "after")]
    text = format_comparison(c)
    assert "only before: only/before" in text and "only after: only/after" in text
    # geometric mean of the runs before is sqrt(8); after 3
    assert math.isclose(c.ratio, 3.0 / math.sqrt(8.0), rel_tol=1e-12)


def test_the_command_prints_the_comparison_and_names_a_bad_folder(tmp_path, capsys):
    a = write_errors(tmp_path / "a", {("s", "b", 0): settled_run(2.0)})
    b = write_errors(tmp_path / "b", {("s", "b", 0): settled_run(4.0)})
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "cells worse 1, better 0 of 1" in out and "x2.000" in out
    assert main(["compare", str(a), str(tmp_path / "missing")]) == 2
    assert "missing: no errors.csv" in capsys.readouterr().err
