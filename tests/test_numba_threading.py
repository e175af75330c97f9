"""The threading layer choice and the serial/parallel policy of the scoring kernel."""

import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from drake_tracker.core.jit.numba_threading import (
    DEFAULT_GOMP_SPINCOUNT,
    DEFAULT_THREADING_LAYER,
    SerialOrParallel,
    configure_threading_layer,
)


@pytest.fixture
def two_numba_threads():
    """Two numba threads for the test (skipped where numba has one), restored after."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here: the policy is always serial")
    previous = numba.get_num_threads()
    numba.set_num_threads(2)
    yield
    numba.set_num_threads(previous)


def test_user_environment_wins_over_the_default(monkeypatch):
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.setenv("NUMBA_THREADING_LAYER", "omp")
    assert configure_threading_layer() == "omp"
    assert os.environ["GOMP_SPINCOUNT"] == DEFAULT_GOMP_SPINCOUNT  # bounded for omp
    monkeypatch.setenv("GOMP_SPINCOUNT", "123")
    configure_threading_layer()
    assert os.environ["GOMP_SPINCOUNT"] == "123"  # the user's own spin wins
    monkeypatch.delenv("NUMBA_THREADING_LAYER")
    assert configure_threading_layer() in (DEFAULT_THREADING_LAYER,
                                           str(numba.config.THREADING_LAYER))


_FORK_PROBE = """
import os, numba, numpy as np
import drake_tracker.core.jit.numba_threading
@numba.njit(parallel=True)
def total(x):
    s = 0.0
    for i in numba.prange(x.shape[0]):
        s += x[i]
    return s
assert total(np.ones(1000)) == 1000.0
pid = os.fork()
if pid == 0:
    os._exit(0 if total(np.ones(1000)) == 1000.0 else 3)
_, status = os.waitpid(pid, 0)
print(numba.threading_layer(), status)
"""


def test_the_default_layer_survives_a_fork():
    """A process that ran a parallel kernel forks (``multiprocessing``'s default on
    Linux), and the child runs one too: with the default layer the child finishes. (GNU
    OpenMP's child is terminated: why ``omp`` is an opt-in.)"""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"}
    out = subprocess.run([sys.executable, "-c", _FORK_PROBE], env=env, check=True,
                         capture_output=True, text=True).stdout.split()
    assert out[-2:] == [DEFAULT_THREADING_LAYER, "0"]


def test_policy_measures_both_then_uses_the_cheaper_and_reprobes(two_numba_threads):
    policy = SerialOrParallel(probe_every=4, smoothing=1.0, warmup_calls=0)
    assert policy.use_parallel() is False  # nothing measured: serial first
    policy.record(False, 1.0, 10)
    assert policy.use_parallel() is True  # then parallel, once
    policy.record(True, 3.0, 10)  # parallel 3x slower (a loaded machine)
    choices = [policy.use_parallel() for _ in range(8)]
    assert choices.count(True) == 2  # only the probes
    policy.record(True, 0.2, 10)  # the load went away
    assert [policy.use_parallel() for _ in range(3)].count(True) >= 2


def test_the_first_call_of_each_compilation_is_not_measured(two_numba_threads):
    policy = SerialOrParallel(smoothing=1.0, warmup_calls=1)
    assert policy.use_parallel() is False
    policy.record(False, 5.0, 10)  # compiles / loads: not measured
    assert policy.use_parallel() is False and policy.cost_per_item[False] is None
    policy.record(False, 1.0, 10)
    assert policy.use_parallel() is True
    policy.record(True, 50.0, 10)  # starts the threads: not measured
    assert policy.use_parallel() is True
    policy.record(True, 0.6, 10)
    assert policy.cost_per_item == {False: 0.1, True: 0.06}
    assert policy.use_parallel() is True


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
    from drake_tracker.core.likelihood.pixel_model import LikelihoodParams, prepare_observation
    from drake_tracker.core.render.batched import BatchedDepthRenderer
    from drake_tracker.core.render.configurations import (
        default_view_configuration,
        random_configurations,
        synthetic_observation,
    )
    from drake_tracker.core.render.fused_score import fused_scores
    from drake_tracker.core.sensors.camera import CameraIntrinsics
    from drake_tracker.robot.model import build_tracker_model, robot_preset

    model = build_tracker_model(robot_preset("apollo"))
    renderer = BatchedDepthRenderer(model, CameraIntrinsics.from_fov(80, 60, np.radians(45)))
    center = default_view_configuration(model)
    observation = prepare_observation(synthetic_observation(renderer, center),
                                      LikelihoodParams())
    q = np.ascontiguousarray(random_configurations(model, 37, seed=2, spread_rad=0.05,
                                                   center=center))
    args = (renderer._frame_tables, renderer._lane_tables, renderer._planes,
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


_THREAD_IDS_SCRIPT = '''
import sys
import numpy as np
from numba import get_thread_id, prange, set_num_threads
sys.path.insert(0, sys.argv[1])
from drake_tracker.core.jit.numba_threading import serial_and_parallel

def thread_ids(out):
    for i in prange(out.shape[0]):
        x = 0.0
        for k in range(200_000):
            x += np.sqrt(k + i)
        out[i] = get_thread_id() + 0.0 * x

serial, parallel = serial_and_parallel(thread_ids)
set_num_threads(2)
a, b = np.zeros(64), np.zeros(64)
serial(a)
parallel(b)
print(len(set(a.tolist())), len(set(b.tolist())))
'''


def test_the_parallel_compilation_stays_parallel_when_loaded_from_the_cache(tmp_path):
    """numba's cache keys a function by name, not by its options (numba issue 6845): the
    parallel compilation must not load the serial one's code. Two processes (the second
    loads both from the cache) run each on 64 iterations with 2 threads."""
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "kernels.py"
    script.write_text(_THREAD_IDS_SCRIPT)
    package_root = str(Path(__file__).resolve().parents[1])
    env = {"NUMBA_NUM_THREADS": "2", "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "PATH": "/usr/bin:/bin"}
    for run in ("compiles", "loads from the cache"):
        result = subprocess.run([sys.executable, str(script), package_root], env=env,
                                capture_output=True, text=True, timeout=300, check=True)
        serial_threads, parallel_threads = map(int, result.stdout.split())
        assert (serial_threads, parallel_threads) == (1, 2), run


def test_the_scoring_kernels_have_cache_files_of_their_own():
    from drake_tracker.core.render import fused_score as render_likelihood

    serial, parallel = render_likelihood._score_serial, render_likelihood._score_parallel
    assert parallel.targetoptions.get("parallel") and not serial.targetoptions.get("parallel")
    assert serial.py_func.__qualname__ != parallel.py_func.__qualname__


def test_probes_that_confirm_the_choice_come_ever_more_rarely(two_numba_threads):
    policy = SerialOrParallel(probe_every=4, smoothing=1.0, warmup_calls=0,
                              max_probe_every=16)
    policy.use_parallel()
    policy.record(False, 1.0, 10)
    policy.use_parallel()
    policy.record(True, 2.0, 10)  # parallel is the dearer

    def calls_until_a_probe() -> int:
        for n in range(1, 100):
            parallel = policy.use_parallel()
            policy.record(parallel, 2.0 if parallel else 1.0, 10)
            if parallel:
                return n
        return -1

    gaps = [calls_until_a_probe() for _ in range(5)]
    assert 1 <= gaps[0] <= 4 and gaps[1:] == [8, 16, 16, 16]
    # The load changes: the next probe finds parallel cheaper, and uses it.
    for _ in range(15):
        assert policy.use_parallel() is False
        policy.record(False, 1.0, 10)
    assert policy.use_parallel() is True
    policy.record(True, 0.5, 10)
    assert policy.probe_interval == 4 and policy.use_parallel() is True
