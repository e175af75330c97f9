"""The threading layer choice and the serial/parallel policy of the scoring kernel."""

import numba
import numpy as np

from drake_tracker.core.numba_threading import (
    DEFAULT_THREADING_LAYER,
    SerialOrParallel,
    configure_threading_layer,
)


def test_user_environment_wins_over_the_default(monkeypatch):
    monkeypatch.setenv("NUMBA_THREADING_LAYER", "omp")
    assert configure_threading_layer() == "omp"
    monkeypatch.delenv("NUMBA_THREADING_LAYER")
    assert configure_threading_layer() in (DEFAULT_THREADING_LAYER,
                                           str(numba.config.THREADING_LAYER))


def test_policy_measures_both_then_uses_the_cheaper_and_reprobes():
    if numba.config.NUMBA_NUM_THREADS < 2:
        return  # one thread: always serial (checked below)
    previous = numba.get_num_threads()
    numba.set_num_threads(2)
    try:
        policy = SerialOrParallel(probe_every=4, smoothing=1.0)
        assert policy.use_parallel() is False  # nothing measured: serial first
        policy.record(False, 1.0, 10)
        assert policy.use_parallel() is True  # then parallel, once
        policy.record(True, 3.0, 10)  # parallel 3x slower (a loaded machine)
        choices = [policy.use_parallel() for _ in range(8)]
        assert choices.count(True) == 2  # only the probes
        policy.record(True, 0.2, 10)  # the load went away
        assert [policy.use_parallel() for _ in range(3)].count(True) >= 2
    finally:
        numba.set_num_threads(previous)


def test_one_thread_is_always_serial():
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        policy = SerialOrParallel()
        policy.record(True, 0.0, 1)
        policy.record(False, 1.0, 1)
        assert not any(policy.use_parallel() for _ in range(100))
    finally:
        numba.set_num_threads(previous)


def test_serial_and_parallel_kernels_give_identical_scores():
    from drake_tracker.core.camera import CameraIntrinsics
    from drake_tracker.core.likelihood import LikelihoodParams, prepare_observation
    from drake_tracker.core.render_batched import BatchedDepthRenderer
    from drake_tracker.core.render_likelihood import fused_scores
    from drake_tracker.core.renderer import (
        default_view_configuration,
        random_configurations,
        synthetic_observation,
    )
    from drake_tracker.robot import build_tracker_model, robot_preset

    model = build_tracker_model(robot_preset("apollo"))
    renderer = BatchedDepthRenderer(model, CameraIntrinsics.from_fov(80, 60, np.radians(45)))
    center = default_view_configuration(model)
    observation = prepare_observation(synthetic_observation(renderer, center),
                                      LikelihoodParams())
    q = np.ascontiguousarray(random_configurations(model, 37, seed=2, spread_rad=0.05,
                                                   center=center))
    args = (renderer._frame_tables, renderer._tables, renderer._planes,
            (renderer._fx, renderer._fy, renderer._cx, renderer._cy), renderer.near_m,
            renderer.far_m, observation)
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        serial = fused_scores(q, *args)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        parallel = fused_scores(q, *args)
    finally:
        numba.set_num_threads(previous)
    np.testing.assert_array_equal(serial, parallel)
    assert np.ptp(serial) > 1.0
