"""A restart keeps what the image does not contradict: H1 chooses among partial restarts
(``core/robustness/least_restart.py``), each joint restarted or kept with its variance
inflated, and takes one only when it fits the image better than the full restart and
than no arm at all."""

import numpy as np
import pytest
from test_restart import CAMERA, apollo_in_view, hand_error_mm, out_of_view_prior

from drake_tracker.core.filter.angle_observation import Restart
from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B
from drake_tracker.core.image_processor import ImageProcessor
from drake_tracker.core.robustness.health import TrackerHealth
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams


@pytest.fixture(scope="module")
def scene():
    """Apollo in view and its depth image."""
    return apollo_in_view(noise_seed=5)


def test_a_partial_restart_keeps_some_joints_and_restarts_the_others():
    """``Restart.keeping``: the kept joints take ``kept()``'s bias step (means kept,
    variances inflated), the others ``apply``'s restart, column by column; keeping none
    is the plain restart."""
    rng = np.random.default_rng(4)
    prior = np.abs(rng.normal(size=(5, 5))) * 0.01
    prior[MEAN_B] = [0.3, -0.2, 0.0, 0.1, 0.05]
    restart = Restart(np.full(5, 0.02**2), np.array([0.1, 0.1, 0.0, 0.1, 0.1]) ** 2,
                      reading_var=np.full(5, 1e-3**2))
    kept = [1, 4]
    out = restart.keeping(np.array(kept)).apply(prior)
    others = [0, 2, 3]
    np.testing.assert_array_equal(out[:, kept], restart.kept().apply(prior)[:, kept])
    np.testing.assert_array_equal(out[:, others], restart.apply(prior)[:, others])
    assert restart.keeping(np.array([], int)).kept_joints is None
    np.testing.assert_array_equal(restart.keeping(np.array([], int)).apply(prior),
                                  restart.apply(prior))


def test_the_partial_restarts_are_each_set_of_a_chain_once():
    from drake_tracker.core.robustness.least_restart import restart_family, restarted_sets

    sets = restarted_sets(4)
    assert sets[0] == (0, 1, 2, 3) and len(set(sets)) == len(sets) and () not in sets
    expected = {(0,), (1,), (2,), (3,), (1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2),
                (0, 1), (2, 3), (0, 1, 2, 3)}
    assert set(sets) == expected
    restart = Restart(np.full(7, 1e-3), np.full(7, 1e-2))
    family = restart_family(restart, np.array([0, 1, 2, 3]), np.array([5, 6]))
    assert len(family) == 2 * len(sets) and family[0] is not None
    assert family[0].kept_joints is None  # the full restart first
    np.testing.assert_array_equal(family[1].kept_joints, [5, 6])  # all, camera kept
    kept = [tuple(m.kept_joints.tolist()) if m.kept_joints is not None else () for m in family]
    assert len(set(kept)) == len(kept)
    assert all(4 not in k for k in kept)  # a joint the restart does not touch


def test_a_restart_keeps_the_biases_the_image_does_not_contradict(scene, no_challenger):
    """The encoders are -6 deg off on arm joints 2 and 4, and the belief knows it, but
    it has put the arm out of view (100 deg more on the shoulder). The full restart to
    the encoders' arm would throw the two known biases away (the hand 40 mm off); the
    restart that keeps them, and restarts the shoulder, fits the image better by far
    more than the margin, and is the one taken."""
    model, truth, frame = scene
    names = model.robot_joint_names
    bias = np.zeros(len(names))
    biased = [names.index(n) for n in ("arm_joint_2", "arm_joint_4")]
    bias[biased] = np.radians(-6.0)
    prior = out_of_view_prior(model, truth, bias)
    known = [model.joint_names.index(names[i]) for i in biased]
    prior[MEAN_A, known] -= bias[biased]
    prior[MEAN_B, known] += bias[biased]
    processor = ImageProcessor(model, CAMERA, resolve_tracker_params(TrackerParams(), model))
    full = hand_error_mm(model, truth, processor.restart.apply(prior)[MEAN_A])
    assert full > 30.0
    due = TrackerHealth(acquired=True, misplaced_since_s=frame.capture_time_s - 1.0)
    outcome = processor.observe(frame, prior, 0.1, due)
    restart = outcome.observation.restart
    assert outcome.restarted and restart.kept_joints is not None
    assert set(known) <= set(restart.kept_joints.tolist())
    assert model.joint_names.index("arm_joint_1") not in restart.kept_joints
    kept_start = restart.apply(prior)
    np.testing.assert_allclose(kept_start[MEAN_B, known], bias[biased])
    assert hand_error_mm(model, truth, kept_start[MEAN_A]) < 0.2 * full
    post = outcome.observation.apply(prior)
    assert hand_error_mm(model, truth, post[MEAN_A]) < 0.2 * full
