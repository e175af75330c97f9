"""The evaluation runner: methods as tracker configurations, tasks, summaries, plots and
resuming."""

import csv

import numpy as np
import pytest

from drake_tracker.evaluate import (
    Task,
    evaluate_run,
    load_errors,
    make_tasks,
    plot_results,
    run_task,
    summarize,
    task_base_params,
    write_summary,
)
from drake_tracker.methods import METHODS, method_params
from drake_tracker.robot import build_tracker_model, robot_preset
from drake_tracker.synthetic import synthetic_run


def test_methods_are_configurations_of_one_tracker():
    assert not method_params("encoders_only").image.enabled
    offset_only = method_params("camera_offset_only")
    assert not offset_only.kalman.robot_joints.has_bias and offset_only.image.blocks == "camera"
    assert not method_params("vision_only").use_joint_readings
    assert method_params("full_fusion").image.enabled
    with pytest.raises(ValueError, match="unknown method"):
        method_params("magic")


def test_task_lists_cover_the_protocol():
    full = make_tasks(False, None, METHODS)
    assert len(full) == 12 * 3 * 10
    quick = make_tasks(True, None, METHODS)
    assert {t.bias for t in quick} == {"none", "constant", "time-varying"}
    assert {"in-out-in", "occlusion", "arm++"} <= {t.sequence for t in quick}
    # The shortened in-out-in still leaves the view within its duration.
    scenario = next(t for t in quick if t.sequence == "in-out-in").scenario()
    tr = scenario.trajectory
    assert tr.excursion_start_s + 2 * tr.excursion_ramp_s < scenario.duration_s


def test_evaluate_run_orders_the_methods_on_a_biased_run():
    model = build_tracker_model(robot_preset("apollo"))
    run = synthetic_run(model, duration_s=2.0, bias_rad=np.radians(3.0), seed=1)
    errors = evaluate_run(run, ("encoders_only", "full_fusion"), min_image_interval_s=0.0)
    encoders = np.nanmedian(errors["encoders_only"]["translation_mm"])
    fusion = np.nanmedian(errors["full_fusion"]["translation_mm"])
    assert fusion < encoders / 3.0


def _fake_rows(tmp_path):
    rng = np.random.default_rng(0)
    (tmp_path / "results").mkdir()
    for seq in ("s-full-arm", "occlusion"):
        path = tmp_path / "results" / f"{seq}__constant__seed0.csv"
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["sequence", "bias", "method", "seed", "time_s", "translation_mm",
                        "rotation_deg"])
            for method in METHODS:
                for t in np.arange(0, 2, 0.05):
                    w.writerow([seq, "constant", method, 0, t, rng.gamma(2, 5), rng.gamma(2)])
    return load_errors(tmp_path)


def test_summary_columns_and_percentiles(tmp_path):
    rows = _fake_rows(tmp_path)
    summary = summarize(rows)
    assert len(summary) == 2 * len(METHODS) * 2
    write_summary(summary, tmp_path)
    with (tmp_path / "summary.csv").open() as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == ["sequence", "bias", "method", "metric", "p1", "p25",
                                     "p50", "p75", "p99"]
        first = next(reader)
    values = [float(r["translation_mm"]) for r in rows
              if (r["sequence"], r["method"]) == (first["sequence"], first["method"])]
    assert float(first["p50"]) == pytest.approx(np.median(values), abs=1e-3)
    paths = plot_results(rows, tmp_path)
    assert all(p.stat().st_size > 0 for p in paths)


def test_a_finished_task_is_not_run_again(tmp_path):
    task = Task("s-full-arm", "constant", 0, 1.0, 0.1, ("encoders_only",))
    result = tmp_path / "results" / f"{task.name}.csv"
    result.parent.mkdir(parents=True)
    result.write_text("sentinel")
    assert run_task(task, tmp_path) == task.name
    assert result.read_text() == "sentinel"


def test_a_parameter_file_reaches_every_task(tmp_path):
    from drake_tracker.params import load_tracker_params, tracker_params_to_yaml

    path = tmp_path / "single.yaml"
    path.write_text("image:\n  annealing_betas: [1.0]\n  num_particles: 200\n")
    tasks = make_tasks(True, None, ("full_fusion",),
                       tracker_params_to_yaml(load_tracker_params(path)))
    for task in tasks:
        params = task_base_params(task)
        assert params.image.annealing_betas == [1.0] and params.image.num_particles == 200
    assert task_base_params(Task("arm", "none", 0, None, 0.1, ("full_fusion",))) is None


def test_a_tiny_evaluation_writes_its_files_and_percentiles(tmp_path):
    """One short sequence, two methods, one seed, through the same entry point as the
    command; the summary is checked against numpy on the written samples."""
    from drake_tracker.evaluate import evaluate

    task = Task("s-full-arm", "constant", 0, 1.5, 0.1, ("encoders_only", "full_fusion"))
    settle_s = 0.5
    summary = evaluate([task], tmp_path, settle_s=settle_s, progress=False)
    for name in ("errors.csv", "summary.csv", "summary.txt", "boxplot_translation_mm.png",
                 "boxplot_rotation_deg.png", "timeseries_s-full-arm_constant.png",
                 f"runs/{task.name}.npz", f"results/{task.name}.csv"):
        assert (tmp_path / name).stat().st_size > 0, name
    with (tmp_path / "errors.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert {r["method"] for r in rows} == {"encoders_only", "full_fusion"}
    assert min(float(r["time_s"]) for r in rows) < settle_s  # every sample is kept
    with (tmp_path / "summary.csv").open() as f:
        written = list(csv.DictReader(f))
    assert len(written) == len(summary) == 2 * 2
    for row in written:
        values = np.array([float(r[row["metric"]]) for r in rows
                           if r["method"] == row["method"] and float(r["time_s"]) >= settle_s])
        assert len(values) >= 15 and np.all(np.isfinite(values))
        for p in (1, 25, 50, 75, 99):
            assert float(row[f"p{p}"]) == pytest.approx(np.percentile(values, p), abs=2e-3)
    # The encoders carry 8.6 deg of bias on every arm joint: their error is large.
    enc = next(r for r in written
               if (r["method"], r["metric"]) == ("encoders_only", "translation_mm"))
    assert float(enc["p50"]) > 50.0
    # Resuming with another protocol in the same folder is refused, by name.
    other = Task("s-full-arm", "constant", 0, 2.0, 0.1, ("encoders_only", "full_fusion"))
    with pytest.raises(ValueError, match="another protocol"):
        evaluate([other], tmp_path, progress=False)


def test_summary_skips_the_settling_time():
    rows = [{"sequence": "s", "bias": "none", "method": "full_fusion", "seed": "0",
             "time_s": f"{t:.2f}", "translation_mm": "1000" if t < 5 else "2",
             "rotation_deg": "1"} for t in np.arange(0, 10, 0.5)]
    summary = summarize(rows, settle_s=5.0)
    assert summary[0]["metric"] == "translation_mm" and summary[0]["p99"] == 2.0


def test_the_command_rejects_unknown_names_and_bad_settling(tmp_path):
    from drake_tracker.cli import main

    out = str(tmp_path / "out")
    with pytest.raises(SystemExit, match="unknown sequence 'nope'"):
        main(["evaluate", "--quick", "--sequences", "nope", "--out", out])
    with pytest.raises(SystemExit, match="unknown method 'magic'"):
        main(["evaluate", "--quick", "--methods", "magic", "--out", out])
    with pytest.raises(SystemExit, match="--settle-s must be >= 0"):
        main(["evaluate", "--quick", "--settle-s", "-1", "--out", out])
