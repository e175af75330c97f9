"""The threading layer choice and the serial/parallel policy of the scoring kernel."""

import os
import subprocess
import sys

import numba
import numpy as np
import pytest
from repo_root import ROOT

from drake_tracker.core.jit.numba_threading import (
    DEFAULT_GOMP_SPINCOUNT,
    FORK_UNSAFE_LAYERS,
    LAYER_PRIORITY,
    SerialOrParallel,
    configure_threading_layer,
)


@pytest.fixture
def two_numba_threads(monkeypatch):
    """Two numba threads for the test (skipped where numba has one), restored after; the
    process's costs measured so far (by the suite's trackers) are hidden from it."""
    from drake_tracker.core.jit import numba_threading

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here: the policy is always serial")
    monkeypatch.setattr(numba_threading, "_latest_costs", {False: (), True: ()})
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
    monkeypatch.setenv("NUMBA_THREADING_LAYER", "workqueue")
    monkeypatch.delenv("GOMP_SPINCOUNT")
    assert configure_threading_layer() == "workqueue"
    assert "GOMP_SPINCOUNT" not in os.environ  # not omp: the environment is left alone


_FORK_PROBE = """
import os, sys, pickle
import numba, numpy as np
from drake_tracker.core.jit import numba_threading
from drake_tracker.core.likelihood.pixel_model import (LikelihoodParams, prepare_observation,
                                                       score_images)
from drake_tracker.core.render.batched import BatchedDepthRenderer
from drake_tracker.core.render.configurations import (default_view_configuration,
                                                      random_configurations,
                                                      synthetic_observation)
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import build_tracker_model, robot_preset

model = build_tracker_model(robot_preset("apollo"))
renderer = BatchedDepthRenderer(model, CameraIntrinsics.from_fov(80, 60, np.radians(45)))
center = default_view_configuration(model)
observation = prepare_observation(synthetic_observation(renderer, center), LikelihoodParams())
q = np.ascontiguousarray(random_configurations(model, 21, seed=3, spread_rad=0.05,
                                               center=center))

def everything():
    images = renderer.render(q)  # kinematics and render_kernel
    return (renderer.kinematics.body_poses(q), images, score_images(images, observation),
            np.concatenate([renderer.score(q, observation) for _ in range(70)]))

numba.set_num_threads(2)
before = everything()  # the parallel kernels run: the layer's threads start
read, write = os.pipe()
pid = os.fork()
if pid == 0:
    os.close(read)
    allowed = numba_threading.parallel_allowed()
    after = everything()
    with os.fdopen(write, "wb") as f:
        pickle.dump((allowed, after), f)
    os._exit(0)
os.close(write)
with os.fdopen(read, "rb") as f:
    data = f.read()
_, status = os.waitpid(pid, 0)
allowed, after = pickle.loads(data) if data else (None, None)
same = after is not None and all(np.array_equal(x, y) for x, y in zip(before, after))
print(numba.threading_layer(), status, allowed, same)
"""


def test_a_forked_child_runs_the_kernels_serially_and_gets_the_same_numbers():
    """A process runs the package's kernels on two threads, then forks
    (``multiprocessing``'s default on Linux), and the child runs them again. Under the
    default layer (GNU OpenMP, which terminates a forked child at its first parallel
    launch), the child must use the serial compilations and give the parent's numbers
    bit for bit: kinematics, rendering, the pixel likelihood and the fused score."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here")
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY")}
    out = subprocess.run([sys.executable, "-c", _FORK_PROBE], env=env, check=True,
                         capture_output=True, text=True).stdout.split()
    layer, status, allowed, same = out[-4:]
    assert layer in LAYER_PRIORITY
    assert status == "0"
    assert same == "True"
    assert allowed == str(layer not in FORK_UNSAFE_LAYERS)


def test_the_default_prefers_openmp():
    """Where numba can load GNU OpenMP (it can on the machines this project runs on),
    the package's default is it: the layer whose second thread helps."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY",
                        "GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    probe = ("import os, numba, numpy as np\n"
             "import drake_tracker.core.jit.numba_threading\n"
             "@numba.njit(parallel=True)\n"
             "def f(x):\n"
             "    return x.sum()\n"
             "f(np.ones(4))\n"
             "print(numba.threading_layer(), os.environ['GOMP_SPINCOUNT'])\n")
    try:
        import numba.np.ufunc.omppool  # noqa: F401
    except ImportError:
        pytest.skip("numba cannot load GNU OpenMP here")
    out = subprocess.run([sys.executable, "-c", probe], env=env, check=True,
                         capture_output=True, text=True).stdout.split()
    assert out[-2:] == [LAYER_PRIORITY[0], DEFAULT_GOMP_SPINCOUNT]


def test_policy_measures_both_then_uses_the_cheaper_and_reprobes(two_numba_threads):
    policy = SerialOrParallel(probe_every=4, window=1, warmup_calls=0)
    assert policy.use_parallel() is False  # nothing measured: serial first
    policy.record(False, 1.0, 10)
    assert policy.use_parallel() is True  # then parallel, once
    policy.record(True, 3.0, 10)  # parallel 3x slower (a loaded machine)
    choices = [policy.use_parallel() for _ in range(8)]
    assert choices.count(True) == 2  # only the probes
    policy.record(True, 0.2, 10)  # the load went away
    assert [policy.use_parallel() for _ in range(3)].count(True) >= 2


def test_one_slowed_call_does_not_flip_the_choice(two_numba_threads):
    """A call can only be slowed by the machine: one preempted parallel call among fast
    ones leaves the policy on the parallel kernel; a lasting slow-down does not."""
    policy = SerialOrParallel(probe_every=1000, window=5, warmup_calls=0)
    policy.use_parallel()
    policy.record(False, 1.5, 10)
    for _ in range(5):
        assert policy.use_parallel()
        policy.record(True, 1.0, 10)
    assert policy.use_parallel()
    policy.record(True, 3.0, 10)  # preempted once
    assert policy.use_parallel() and policy.cost_per_item[True] == 0.1
    for _ in range(5):  # the machine stays loaded: the slow calls fill the window
        policy.record(True, 3.0, 10)
    assert not policy.use_parallel()


def test_the_first_call_of_each_compilation_is_not_measured(two_numba_threads, monkeypatch):
    from drake_tracker.core.jit import numba_threading

    monkeypatch.setattr(numba_threading, "_calls_in_process", {False: 0, True: 0})
    policy = SerialOrParallel(window=1, warmup_calls=1)
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
    # The warm-up is the process's, not each policy's, and so are the costs: a second
    # policy (another tracker's renderer) starts from the process's latest costs, so its
    # first image runs parallel at once, not a serial sweep to learn what is known.
    second = SerialOrParallel(window=1, warmup_calls=1)
    assert second.cost_per_item == {False: 0.1, True: 0.06}
    assert second.use_parallel() is True
    second.record(True, 0.5, 10)  # its own measurement replaces the inherited one
    assert second.cost_per_item == {False: 0.1, True: 0.05}
    assert [second.use_parallel() for _ in range(3)] == [True] * 3
    # Where the process found serial cheaper, a new policy starts serial.
    second.record(True, 2.0, 10)
    third = SerialOrParallel(window=1, warmup_calls=1)
    assert third.cost_per_item == {False: 0.1, True: 0.2} and third.use_parallel() is False


def test_a_new_policy_keeps_the_process_window(two_numba_threads, monkeypatch):
    """The inherited costs are calls of the window: one slow parallel call at a new
    tracker's start (the machine busy) does not flip it to serial; a lasting one does."""
    from drake_tracker.core.jit import numba_threading

    monkeypatch.setattr(numba_threading, "_calls_in_process", {False: 9, True: 9})
    first = SerialOrParallel(window=5, warmup_calls=1)
    first.record(False, 1.0, 10)
    for _ in range(5):
        first.record(True, 0.4, 10)
    second = SerialOrParallel(window=5, warmup_calls=1)
    assert second.cost_per_item == {False: 0.1, True: 0.04}
    assert second.use_parallel()
    second.record(True, 1.2, 10)  # slowed: 0.12 per item, dearer than serial's 0.1
    assert second.use_parallel() and second.cost_per_item[True] == 0.04
    for _ in range(4):
        second.record(True, 1.2, 10)
    assert second.cost_per_item[True] == pytest.approx(0.12) and not second.use_parallel()
    assert first.cost_per_item[True] == 0.04  # each policy's window is its own


def test_a_forked_child_warms_up_afresh(monkeypatch):
    """A forked child's threads are its own: its first calls are warm-up calls again."""
    from drake_tracker.core.jit import numba_threading

    monkeypatch.setattr(numba_threading, "_calls_in_process", {False: 7, True: 9})
    monkeypatch.setattr(numba_threading, "_latest_costs", {False: (1.0,), True: (0.5,)})
    # (restored after the test: this process is no fork)
    monkeypatch.setattr(numba_threading, "_forked_after_unsafe_start", False)
    numba_threading._after_fork_in_child()
    assert numba_threading._calls_in_process == {False: 0, True: 0}
    assert numba_threading._latest_costs == {False: (), True: ()}


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

    script = tmp_path / "kernels.py"
    script.write_text(_THREAD_IDS_SCRIPT)
    package_root = str(ROOT)
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
    policy = SerialOrParallel(probe_every=4, window=1, warmup_calls=0,
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
