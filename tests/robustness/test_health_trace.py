"""``replay_run``'s per-image callback, and ``examples/health_trace.py`` built on it: the
callback sees every accepted image and changes nothing; the trace prints one line per
image in its window, naming the joints it reports."""

import numpy as np
from example_modules import load_example

from drake_tracker.evaluation.tasks import protocol_params
from drake_tracker.io.recording import RecordedRun
from drake_tracker.io.replay import replay_run
from drake_tracker.io.synthetic import synthetic_run


def test_the_image_callback_sees_every_image_and_changes_no_estimate(apollo):
    run = synthetic_run(apollo, duration_s=0.8, seed=3)
    params = protocol_params(run, "full_fusion", 0.1, tracker_seed=3)
    params.image.num_particles = 50
    seen = []
    traced = replay_run(run, params, apollo,
                        on_image=lambda tracker, frame: seen.append(
                            (frame.sequence, tracker.num_images_applied)))
    plain = replay_run(run, params, apollo)
    np.testing.assert_array_equal(traced.X_CE, plain.X_CE)
    arrived = np.sort(run.image_arrival_times_s) < run.reading_times_s[-1]
    assert len(seen) == int(arrived.sum())
    assert [s for s, _ in seen] == list(np.argsort(run.image_arrival_times_s,
                                                   kind="stable")[:len(seen)])
    applied = [a for _, a in seen]
    assert applied == sorted(applied) and applied[-1] == traced.num_images_applied


def test_the_health_trace_prints_each_image_of_its_window(apollo, tmp_path):
    path = tmp_path / "run.npz"
    synthetic_run(apollo, duration_s=0.8, seed=1).save(path)
    run = RecordedRun.load(path)
    trace = load_example("health_trace.py")
    lines = trace.trace_lines(run, seed=1, from_s=0.3, to_s=0.6, every_s=0.0,
                              min_image_interval_s=0.1)
    for name in apollo.robot_joint_names:
        assert name in lines[0]
    captured = run.image_capture_times_s
    expected = np.sort(captured[(captured >= 0.3) & (captured <= 0.6)])
    times = [float(line.split(" s ")[0]) for line in lines[1:]]
    np.testing.assert_allclose(times, expected, atol=0.006)
    for line in lines[1:]:
        error_mm = float(line.split("error")[1].split("mm")[0])
        assert np.isfinite(error_mm) and error_mm < 1000
