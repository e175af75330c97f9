"""The window fit of the cameras' offsets (``core/calibration/window_fit.py``): its
configurations against a naive reference, its maximum on a likelihood whose maximum is
known, its checks."""

import numpy as np
import pytest

from drake_tracker.core.calibration.window_fit import (
    WindowImage,
    WindowLayout,
    fit_window,
    window_log_likelihood,
)

#: 5 robot joints (biases fitted on 0, 2, 3), two cameras of six virtual joints each,
#: interleaved with the robot's in the model's order.
ROBOT = np.array([0, 1, 2, 6, 7])
LAYOUT = WindowLayout(17, ROBOT, np.array([0, 2, 3]),
                      {"a": np.array([3, 4, 5, 8, 9, 10]), "b": np.arange(11, 17)})


def naive_configuration(theta, reading, camera):
    q = np.zeros(17)
    for k, joint in enumerate(ROBOT):
        bias = theta[list(LAYOUT.bias_joints).index(k)] if k in LAYOUT.bias_joints else 0.0
        q[joint] = reading[k] - bias
    start = 3 + 6 * ["a", "b"].index(camera)
    q[LAYOUT.camera_joints[camera]] = theta[start:start + 6]
    return q


def test_a_configuration_is_the_readings_less_the_biases_and_its_cameras_offsets():
    rng = np.random.default_rng(0)
    thetas = rng.normal(size=(4, LAYOUT.size))
    reading = rng.normal(size=5)
    for camera in ("a", "b"):
        got = LAYOUT.configurations(thetas, reading, camera)
        want = np.array([naive_configuration(t, reading, camera) for t in thetas])
        np.testing.assert_array_equal(got, want)
    both = LAYOUT.configurations(thetas[0], reading)[0]
    for camera in ("a", "b"):
        joints = LAYOUT.camera_joints[camera]
        np.testing.assert_array_equal(both[joints], naive_configuration(
            thetas[0], reading, camera)[joints])
    np.testing.assert_array_equal(LAYOUT.offsets(thetas[1], "b"), thetas[1][9:15])


def quadratic_images(theta_true, seed=1):
    """Images whose log-likelihood is a Gaussian in the configuration, centred on the
    one ``theta_true`` gives, with correlated (ill-conditioned) precisions: the ridge of a
    camera offset that trades against an arm bias."""
    rng = np.random.default_rng(seed)
    images = []
    for k in range(8):
        camera = "ab"[k % 2]
        reading = rng.normal(0.0, 0.5, 5)
        centre = LAYOUT.configurations(theta_true, reading, camera)[0]
        A = rng.normal(size=(17, 17)) / 4.0 + np.diag(rng.uniform(0.5, 5.0, 17))

        def score(q, centre=centre, A=A):
            d = (q - centre) @ A.T
            return -0.5 * np.sum(d * d, axis=1) * 100.0

        images.append(WindowImage(camera, reading, score))
    return images


def test_the_fit_climbs_to_a_known_maximum_from_a_wrong_start():
    rng = np.random.default_rng(2)
    theta_true = rng.normal(0.0, 0.05, LAYOUT.size)
    images = quadratic_images(theta_true)
    scale = np.full(LAYOUT.size, 0.02)
    start = theta_true + rng.normal(0.0, 0.03, LAYOUT.size)
    fit = fit_window(LAYOUT, images, start, scale, evaluations=6000, seed=3)
    assert fit.log_likelihood > fit.log_likelihood_start
    assert fit.log_likelihood == pytest.approx(
        window_log_likelihood(LAYOUT, images, fit.theta)[0])
    np.testing.assert_allclose(fit.theta, theta_true, atol=2e-3)
    np.testing.assert_array_equal(fit.offsets("a"), fit.theta[3:9])
    np.testing.assert_array_equal(fit.biases, fit.theta[:3])
    assert fit.evaluations <= 6000 + 24
    again = fit_window(LAYOUT, images, start, scale, evaluations=6000, seed=3)
    np.testing.assert_array_equal(again.theta, fit.theta)  # seeded


@pytest.mark.parametrize("change, message", [
    (lambda im, th, sc: ([], th, sc), "no image"),
    (lambda im, th, sc: ([WindowImage("c", im[0].reading, im[0].score)], th, sc),
     "cameras ['c']"),
    (lambda im, th, sc: ([WindowImage("a", np.zeros(4), im[0].score)], th, sc),
     "readings (4,)"),
    (lambda im, th, sc: (im, th[:-1], sc), "theta_start must be 15"),
    (lambda im, th, sc: (im, th, np.where(np.arange(15) == 2, np.nan, sc)),
     "scale must be 15 finite"),
    (lambda im, th, sc: (im, th, -sc), "scale must be > 0"),
])
def test_the_fit_names_what_is_wrong_with_its_input(change, message):
    images = quadratic_images(np.zeros(LAYOUT.size))
    args = change(images, np.zeros(LAYOUT.size), np.full(LAYOUT.size, 0.01))
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]")):
        fit_window(LAYOUT, *args, evaluations=200)
    with pytest.raises(ValueError, match="evaluations must be >= 100"):
        fit_window(LAYOUT, images, np.zeros(LAYOUT.size), np.full(LAYOUT.size, 0.01),
                   evaluations=10)
