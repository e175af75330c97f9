"""A bias jump is looked for only on a joint whose move the image would see."""

import numpy as np
import pytest

from drake_tracker.core.likelihood.pixel_model import LikelihoodParams
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.configurations import default_view_configuration
from drake_tracker.core.robustness.jump_visibility import changed_visible_pixels, jump_testable
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import build_tracker_model, robot_preset

CAMERA = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
PARAMS = LikelihoodParams()


def test_changed_pixels_count_only_what_the_image_sees():
    base = np.full((4, 5), np.inf)
    base[1:3, 1:3] = 1.0  # a 2x2 robot at 1 m
    moved = np.full((4, 5), np.inf)
    moved[1:3, 2:4] = 1.0  # moved one column right: 2 pixels lost, 2 gained
    deeper = base.copy()
    deeper[1, 1] = 1.001  # within 3 sigma: no change
    deeper[2, 2] = 1.2
    observed = np.where(np.isfinite(base), base, 2.0)
    counts = changed_visible_pixels(base, np.stack([moved, deeper, base]), observed, PARAMS)
    np.testing.assert_array_equal(counts, [4, 1, 0])
    # An occluder in front of both renderings hides the change; invalid pixels say nothing.
    occluded = observed.copy()
    occluded[:, 1] = 0.5
    invalid = observed.copy()
    invalid[:, 3] = np.nan
    assert changed_visible_pixels(base, moved[None], occluded, PARAMS)[0] == 2
    # Unless nearer is not an occluder (an image that contradicts the belief).
    assert changed_visible_pixels(base, moved[None], occluded, PARAMS, occluders=False)[0] == 4
    assert changed_visible_pixels(base, moved[None], invalid, PARAMS)[0] == 2


def _changed_numpy(base_m, moved_m, observed_m, params, occluders=True):
    """The former whole-image numpy count: the reference for the compiled one."""
    from drake_tracker.core.likelihood.pixel_model import pixel_sigma, valid_pixels

    base = np.asarray(base_m, float)[None]
    moved = np.asarray(moved_m, float)
    observed = np.asarray(observed_m, float)
    valid = valid_pixels(observed, params)
    z = np.where(valid, observed, 1.0)[None]
    sigma3 = 3.0 * pixel_sigma(z, params)
    with np.errstate(invalid="ignore"):
        differ = np.isfinite(base) != np.isfinite(moved)
        differ |= np.isfinite(base) & np.isfinite(moved) & (np.abs(base - moved) > sigma3)
        nearer = np.minimum(base, moved)
        seen = z >= nearer - sigma3 if occluders else True
    return np.count_nonzero(differ & seen & valid[None], axis=(1, 2))


@pytest.mark.parametrize("seed", range(3))
def test_the_compiled_count_equals_the_whole_image_numpy_count(seed):
    rng = np.random.default_rng(seed)
    base = np.where(rng.random((60, 80)) < 0.3, rng.uniform(0.5, 2.0, (60, 80)), np.inf)
    moved = np.repeat(base[None], 14, axis=0)
    change = rng.random(moved.shape) < 0.1
    moved[change] = np.where(rng.random(change.sum()) < 0.5, np.inf,
                             rng.uniform(0.5, 2.0, change.sum()))
    moved[rng.random(moved.shape) < 0.05] += rng.normal(0.0, 0.01, 1)  # near 3 sigma
    moved[0, 0, :5] = np.nan
    observed = np.where(np.isfinite(base), base, 2.5) + rng.normal(0.0, 0.05, base.shape)
    observed[rng.random(base.shape) < 0.1] = np.nan
    observed[rng.random(base.shape) < 0.05] = 0.3  # occluders in front
    observed[rng.random(base.shape) < 0.02] = 20.0  # beyond max_depth_m
    for occluders in (True, False):
        np.testing.assert_array_equal(
            changed_visible_pixels(base, moved, observed, PARAMS, occluders),
            _changed_numpy(base, moved, observed, PARAMS, occluders))
    with pytest.raises(ValueError, match="one image size"):
        changed_visible_pixels(base, moved[:, :, 1:], observed, PARAMS)


@pytest.fixture(scope="module")
def apollo_view():
    model = build_tracker_model(robot_preset("apollo"))
    renderer = make_renderer(model, CAMERA)
    mean = default_view_configuration(model)
    base = renderer.render(mean[None])[0].astype(float)
    return model, renderer, mean, base


def test_a_joint_whose_move_is_hidden_cannot_test_a_jump(apollo_view):
    model, renderer, mean, base = apollo_view
    shoulder, elbow = (model.joint_names.index(n) for n in ("arm_joint_2", "arm_joint_4"))
    joints = np.array([shoulder, elbow])
    step = np.full(len(mean), np.radians(8.6))
    clear = np.where(np.isfinite(base), base, 2.5)
    assert jump_testable(renderer, mean, joints, step, base, clear, PARAMS, 30).tolist() == [
        True, True]
    # Something 0.3 m from the camera in front of every pixel the elbow's move changes.
    q = np.repeat(mean[None], 2, axis=0)
    q[:, elbow] += [step[elbow], -step[elbow]]
    moved = renderer.render(q).astype(float)
    both = np.isfinite(moved) & np.isfinite(base)[None]
    gap = np.abs(np.where(both, moved, 0.0) - np.where(both, base[None], 0.0))
    forearm = np.any((np.isfinite(moved) != np.isfinite(base)[None]) | (gap > 0.01), axis=0)
    hidden = np.where(forearm, 0.3, clear)
    testable = jump_testable(renderer, mean, joints, step, base, hidden, PARAMS, 30)
    assert testable.tolist() == [True, False]
    # Nothing to see at all: no joint can be tested.
    wall = np.full_like(clear, 0.3)
    assert not jump_testable(renderer, mean, joints, step, base, wall, PARAMS, 30).any()


def test_the_gate_equals_rendering_both_moves_of_every_joint(apollo_view):
    """``jump_testable`` renders -step only for the joints +step did not show: the same
    answer as the plain form, both moves of every joint rendered and the larger count
    taken, on images that hide the arm in part at random and at several thresholds."""
    model, renderer, mean, base = apollo_view
    joints = np.array(model.robot_joint_indices)
    step = np.full(len(mean), np.radians(8.6))
    rng = np.random.default_rng(3)
    q = np.repeat(mean[None], 2 * joints.size, axis=0)
    rows = np.arange(joints.size)
    q[rows, joints] += step[joints]
    q[joints.size + rows, joints] -= step[joints]
    moved = renderer.render(q)
    answers, by_minus_only = set(), 0
    for trial in range(6):
        observed = np.where(np.isfinite(base), base, 2.5)
        observed[rng.random(base.shape) < 0.2 * trial] = 0.3  # hidden by something near
        counts = changed_visible_pixels(base, moved, observed, PARAMS)
        for min_pixels in (1, 5, 30, 300):
            plain = np.maximum(counts[: joints.size], counts[joints.size:]) >= min_pixels
            by_minus_only += int(np.sum((counts[: joints.size] < min_pixels) & plain))
            gate = jump_testable(renderer, mean, joints, step, base, observed, PARAMS,
                                 min_pixels)
            np.testing.assert_array_equal(gate, plain)
            answers.add(tuple(gate))
    assert len(answers) > 3  # the cases differ: all, some and none of the joints
    assert by_minus_only > 0  # and some joints show only their -step move
