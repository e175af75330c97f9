"""Same inputs and seed, same estimates: whatever the numba thread count, and run again."""

import numba
import numpy as np
import pytest

from drake_tracker.io.replay import replay_run
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model, robot_preset


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs 2 numba threads")
def test_one_thread_and_two_threads_give_identical_estimates():
    model = build_tracker_model(robot_preset("apollo"))
    run = synthetic_run(model, duration_s=0.8, encoder_rate_hz=200.0, seed=4)
    params = TrackerParams()
    params.image.num_particles = 20
    before = numba.get_num_threads()
    try:
        results = []
        for threads in (1, 2, 1):
            numba.set_num_threads(threads)
            results.append(replay_run(run, params, model=model))
    finally:
        numba.set_num_threads(before)
    assert results[0].num_images_applied >= 5
    for other in results[1:]:
        np.testing.assert_array_equal(other.positions, results[0].positions)
        np.testing.assert_array_equal(other.X_CE, results[0].X_CE)
