"""The evaluation runner: methods as tracker configurations, tasks, summaries, plots and
resuming."""

import csv
import json

import numpy as np
import pytest

from drake_tracker.evaluation import (
    ResultStore,
    Task,
    evaluate,
    evaluate_run,
    make_tasks,
    plot_results,
    summarize,
    task_base_params,
    write_summary,
)
from drake_tracker.evaluation.methods import METHODS, method_params
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.robot.model import build_tracker_model, robot_preset


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
    from drake_tracker.evaluation.tasks import QUICK_EXTRA_CASES

    # Five sequences x three biases, the extra cases, three seeds each by default.
    assert len(quick) == (5 * 3 + len(QUICK_EXTRA_CASES)) * 3
    assert {t.seed for t in quick} == {0, 1, 2}
    assert {"none", "constant", "time-varying"} <= {t.bias for t in quick}
    assert {t.duration_s for t in make_tasks(True, 1, METHODS, duration_s=2.0)} == {2.0}
    assert {"in-out-in", "occlusion", "arm++"} <= {t.sequence for t in quick}
    # The shortened in-out-in still leaves the view within its duration.
    scenario = next(t for t in quick if t.sequence == "in-out-in").scenario()
    tr = scenario.trajectory
    assert tr.excursion_start_s + 2 * tr.excursion_ramp_s < scenario.duration_s


def test_the_full_mode_runs_a_named_extra_preset_at_its_own_length():
    tasks = make_tasks(False, 2, ("full_fusion",),
                       sequences=("in-out-in-2cam", "occlusion-lasting-2cam", "arm"))
    cases = {(t.sequence, t.bias) for t in tasks}
    assert cases == {(q, b) for q in ("in-out-in-2cam", "occlusion-lasting-2cam", "arm")
                     for b in ("none", "constant", "time-varying")}
    assert len(tasks) == 9 * 2 and {t.duration_s for t in tasks} == {None}
    lengths = {t.sequence: t.scenario().duration_s for t in tasks}
    assert lengths == {"in-out-in-2cam": 60.0, "occlusion-lasting-2cam": 30.0, "arm": 60.0}
    assert len(next(t for t in tasks if t.sequence == "in-out-in-2cam").scenario().cameras) == 2
    # The quick mode keeps its own cases: a two-camera cell, not every bias of it.
    quick = make_tasks(True, 1, ("full_fusion",), sequences=("occlusion-lasting-2cam",))
    assert [(t.sequence, t.bias) for t in quick] == [("occlusion-lasting-2cam", "constant")]
    with pytest.raises(ValueError, match="unknown sequence 'nope' for this mode"):
        make_tasks(True, 1, ("full_fusion",), sequences=("in-out-in-2cam", "nope"))


def test_evaluate_run_orders_the_methods_on_a_biased_run():
    model = build_tracker_model(robot_preset("apollo"))
    run = synthetic_run(model, duration_s=2.0, bias_rad=np.radians(3.0), seed=1)
    errors = evaluate_run(run, ("encoders_only", "full_fusion"), min_image_interval_s=0.0)
    encoders = np.nanmedian(errors["encoders_only"]["translation_mm"])
    fusion = np.nanmedian(errors["full_fusion"]["translation_mm"])
    assert fusion < encoders / 3.0


def test_the_task_seed_reaches_the_tracker(monkeypatch):
    import drake_tracker.io.replay as offline
    import drake_tracker.kernel_warm_up as warm_up

    seen = []

    def fake_replay(run, params, model, sample_times_s, on_image=None):
        seen.append(params.image.seed)
        raise RuntimeError("stop here")

    monkeypatch.setattr(offline, "replay_run", fake_replay)
    monkeypatch.setattr(warm_up, "_loaded_in_process", True)
    model = build_tracker_model(robot_preset("apollo"))
    run = synthetic_run(model, duration_s=0.2, bias_rad=0.0, seed=1)
    from drake_tracker.params.tracker_params import TrackerParams

    base = TrackerParams()
    base.image.seed = 40
    for tracker_seed in (0, 2):
        with pytest.raises(RuntimeError, match="stop here"):
            evaluate_run(run, ("full_fusion",), base_params=base, tracker_seed=tracker_seed)
    assert seen == [40, 42]


def test_a_process_loads_the_kernels_before_its_first_replay_only(monkeypatch):
    """A worker's first task paid for loading (or compiling) the kernels inside its image
    updates and decision: they are loaded before, once per process, and timed apart."""
    import drake_tracker.io.replay as offline
    import drake_tracker.kernel_warm_up as warm_up

    calls, order = [], []
    monkeypatch.setattr(warm_up, "_loaded_in_process", False)
    monkeypatch.setattr(warm_up, "warm_up_tracker_kernels",
                        lambda model, camera, params: calls.append((model, camera)) or 7.0)

    def fake_replay(run, params, model, sample_times_s, on_image=None):
        order.append(len(calls))
        raise RuntimeError("stop here")

    monkeypatch.setattr(offline, "replay_run", fake_replay)
    model = build_tracker_model(robot_preset("apollo"))
    run = synthetic_run(model, duration_s=0.2, bias_rad=0.0, seed=1)
    first, second = {}, {}
    for wall_s in (first, second):
        with pytest.raises(RuntimeError, match="stop here"):
            evaluate_run(run, ("full_fusion",), wall_s=wall_s)
    assert len(calls) == 1 and calls[0][1] == run.camera_intrinsics
    assert order == [1, 1]  # loaded before the first replay, not again
    assert first == {"kernel_warm_up": 7.0} and second == {}


def _write_fake_results(out_dir, seeds=(0,), sequences=("s-full-arm", "occlusion")):
    rng = np.random.default_rng(0)
    (out_dir / "results").mkdir(parents=True, exist_ok=True)
    for seq in sequences:
        for seed in seeds:
            path = out_dir / "results" / f"{seq}__constant__seed{seed}.csv"
            with path.open("w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["sequence", "bias", "method", "seed", "time_s", "translation_mm",
                            "rotation_deg"])
                for method in METHODS:
                    for t in np.arange(0, 2, 0.05):
                        w.writerow([seq, "constant", method, seed, t,
                                    (1 + seed) * rng.gamma(2, 5), rng.gamma(2)])


def test_the_store_writes_compressed_reproducible_errors_and_reads_older_plain_ones(tmp_path):
    """A payload's errors go to ``results/<task>.csv.gz`` (the same bytes for the same
    errors: no time stamp in the gzip header); a folder of plain ``.csv`` results (an
    older evaluation) is resumed and read the same; the compressed file wins over a plain
    one of the same task."""
    import gzip

    from drake_tracker.evaluation import ResultStore

    _write_fake_results(tmp_path, sequences=("s-full-arm",))  # a plain, older result
    store = ResultStore(tmp_path)
    older = Task("s-full-arm", "constant", 0, None, 0.1, METHODS)
    newer = Task("occlusion", "constant", 0, None, 0.1, METHODS)
    assert store.is_done(older) and not store.is_done(newer)
    plain_rows = store.load_rows([older])
    assert len(plain_rows) == len(METHODS) * 40
    text = (tmp_path / "results" / f"{older.name}.csv").read_text()
    store.write({"name": newer.name, "csv": text.replace("s-full-arm", "occlusion"),
                 "simulated_s": 2.0})
    first = store.result_path(newer.name).read_bytes()
    store.write({"name": newer.name, "csv": text.replace("s-full-arm", "occlusion"),
                 "simulated_s": 2.0})
    assert store.result_path(newer.name).read_bytes() == first
    assert store.result_path(newer.name).name == f"{newer.name}.csv.gz"
    assert gzip.decompress(first).decode() == text.replace("s-full-arm", "occlusion")
    assert store.is_done(newer) and len(store.load_metas([older, newer])) == 1
    rows = store.load_rows()
    assert [r["sequence"] for r in rows] == ["occlusion"] * len(plain_rows) + [
        "s-full-arm"] * len(plain_rows)
    assert rows[len(plain_rows):] == plain_rows
    # Compressing an older folder's file in place changes nothing that is read.
    plain = tmp_path / "results" / f"{older.name}.csv"
    plain.with_name(plain.name + ".gz").write_bytes(gzip.compress(b"sequence,bias\n"))
    assert store.load_rows([older]) == []
    plain.with_name(plain.name + ".gz").write_bytes(gzip.compress(plain.read_bytes()))
    assert store.load_rows([older]) == plain_rows


def _fake_rows(tmp_path):
    _write_fake_results(tmp_path)
    return ResultStore(tmp_path).load_rows()


def test_summary_columns_and_percentiles(tmp_path):
    rows = _fake_rows(tmp_path)
    summary = summarize(rows)
    assert len(summary) == 2 * len(METHODS) * 2
    write_summary(summary, tmp_path)
    with (tmp_path / "summary.csv").open() as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == ["sequence", "bias", "method", "metric", "p1", "p25",
                                     "p50", "p75", "p99", "seeds", "median_over_seeds",
                                     "worst_seed_median", "worst_seed"]
        first = next(reader)
    values = [float(r["translation_mm"]) for r in rows
              if (r["sequence"], r["method"]) == (first["sequence"], first["method"])]
    assert float(first["p50"]) == pytest.approx(np.median(values), abs=1e-3)
    paths = plot_results(rows, tmp_path)
    assert all(p.stat().st_size > 0 for p in paths)


def test_the_summary_reports_the_median_over_seeds_and_the_worst_seed(tmp_path):
    _write_fake_results(tmp_path, seeds=(0, 1, 2), sequences=("arm",))
    rows = ResultStore(tmp_path).load_rows()
    summary = summarize(rows, settle_s=0.5)
    for row in summary:
        per_seed = {s: np.median([float(r[row["metric"]]) for r in rows
                                  if (r["method"], int(r["seed"])) == (row["method"], s)
                                  and float(r["time_s"]) >= 0.5]) for s in (0, 1, 2)}
        assert row["seeds"] == 3
        assert row["median_over_seeds"] == pytest.approx(np.median(list(per_seed.values())))
        worst = max(per_seed, key=per_seed.get)
        assert (row["worst_seed"], row["worst_seed_median"]) == (worst, pytest.approx(
            per_seed[worst]))
    # The translation errors were drawn scaled by (1 + seed): seed 2 is the worst.
    assert {r["worst_seed"] for r in summary if r["metric"] == "translation_mm"} == {2}


def test_a_finished_task_is_not_run_again(tmp_path):
    """Result files present: nothing is simulated, the summary is read from them."""
    _write_fake_results(tmp_path, sequences=("s-full-arm",))
    task = Task("s-full-arm", "constant", 0, 2.0, 0.1, METHODS)
    summary = evaluate([task], tmp_path, settle_s=0.0, progress=False)
    assert not (tmp_path / "runs").exists()
    assert len(summary) == 2 * len(METHODS)
    assert (tmp_path / "failures.json").read_text().strip() == "{}"


def test_a_parameter_file_reaches_every_task(tmp_path):
    from drake_tracker.params.loading import load_tracker_params, tracker_params_to_yaml

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
    task = Task("s-full-arm", "constant", 0, 1.5, 0.1, ("encoders_only", "full_fusion"))
    settle_s = 0.5
    summary = evaluate([task], tmp_path, settle_s=settle_s, progress=False)
    for name in ("errors.csv", "summary.csv", "summary.txt", "boxplot_s-full-arm.png",
                 "paper_comparison.md", "health_confusion.md",
                 "timeseries_s-full-arm_constant.png",
                 f"runs/{task.name}.npz", f"results/{task.name}.csv.gz",
                 f"results/{task.name}.json", "protocol.json", "failures.json"):
        assert (tmp_path / name).stat().st_size > 0, name
    with (tmp_path / "errors.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert {r["method"] for r in rows} == {"encoders_only", "full_fusion"}
    assert min(float(r["time_s"]) for r in rows) < settle_s  # every sample is kept
    # The tracker's health at each sample; none for the encoders alone.
    assert {r["health"] for r in rows if r["method"] == "encoders_only"} == {""}
    states = {r["health"] for r in rows if r["method"] == "full_fusion"}
    assert states <= {"", "tracking", "uncertain", "lost"} and "tracking" in states
    # The state just after each image, in its own table: the tracker's methods only.
    with (tmp_path / "image_health.csv").open() as f:
        images = list(csv.DictReader(f))
    assert {r["method"] for r in images} == {"full_fusion"} and len(images) > 5
    meta = json.loads((tmp_path / f"results/{task.name}.json").read_text())
    assert len(images) == meta["decision_times"]["full_fusion"]["images"]  # paced: 0.1 s
    assert len(images) < 1.5 / 0.1 + 2
    assert {r["health"] for r in images} <= {"tracking", "uncertain", "lost"}
    assert "Just after each image" in (tmp_path / "health_confusion.md").read_text()
    # Each camera's frame against the truth: for the only camera, the hand in its frame
    # is errors.csv's output, sample by sample (the world is the model here); the
    # encoders alone estimate no camera.
    with (tmp_path / "cameras.csv").open() as f:
        cameras = list(csv.DictReader(f))
    assert {(r["method"], r["camera"]) for r in cameras} == {("full_fusion", "camera")}
    fusion = [r for r in rows if r["method"] == "full_fusion"]
    assert [r["time_s"] for r in cameras] == [r["time_s"] for r in fusion]
    for key, column in (("hand_mm", "translation_mm"), ("hand_deg", "rotation_deg")):
        np.testing.assert_allclose([float(r[key]) for r in cameras],
                                   [float(r[column]) for r in fusion], atol=2e-4)
    assert "| s-full-arm | constant | full_fusion | camera | 1 |" in (
        tmp_path / "cameras.md").read_text()
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
    # protocol.json records what the results depend on, as the worker saw it.

    protocol = json.loads((tmp_path / "protocol.json").read_text())
    (env,) = protocol["task_environments"]
    assert set(env["versions"]) == {"drake", "numpy", "numba", "llvmlite", "python"}
    assert env["cpu"] and env["numba_threads"] >= 1 and env["tasks"] == 1
    assert env["compile_target"]  # e.g. znver4: what the kernels' rounding depends on
    # The stored task keeps where the tracker's image time went (``DecisionTimes``): one
    # image observed per 0.1 s of the 1.5 s run at most, split into update and decision.
    meta = json.loads((tmp_path / f"results/{task.name}.json").read_text())
    times = meta["decision_times"]
    assert list(times) == ["full_fusion"]  # the encoders alone observe no image
    assert 5 <= times["full_fusion"]["images"] <= 16
    assert times["full_fusion"]["update_s"] > 0 and times["full_fusion"]["decision_s"] > 0
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
    from drake_tracker.cli.main import main

    out = str(tmp_path / "out")
    with pytest.raises(SystemExit, match="unknown sequence 'nope'"):
        main(["evaluate", "--quick", "--sequences", "nope", "--out", out])
    with pytest.raises(SystemExit, match="unknown method 'magic'"):
        main(["evaluate", "--quick", "--methods", "magic", "--out", out])
    with pytest.raises(SystemExit, match="--settle-s must be >= 0"):
        main(["evaluate", "--quick", "--settle-s", "-1", "--out", out])
    with pytest.raises(SystemExit, match="--address is for --executor ray"):
        main(["evaluate", "--quick", "--address", "auto", "--out", out])
    with pytest.raises(SystemExit, match="--workers must be >= 1"):
        main(["evaluate", "--quick", "--workers", "0", "--out", out])
    assert not (tmp_path / "out").exists()  # nothing written before the checks pass
