"""Each camera's mounting error and the arm's biases, fitted to a window of images of
every camera at once.

The parameters are θ = (b, o_1, ..., o_K): b the biases of the robot joints
``WindowLayout.bias_joints``, held constant over the window (every other robot joint at
its reading), and o_k camera k's six offsets (its virtual joints: x, y, z in m, then
rx, ry, rz in rad). Image i, of camera k, captured with the encoders reading r_i, is
scored at the configuration

    q_i(θ)[robot] = r_i − b,    q_i(θ)[camera k's virtual joints] = o_k,

by the tracker's own pixel likelihood ℓ_i (§4 of ``docs/method.md``, without the
occlusion estimate), and the window's log-likelihood is the plain sum

    L(θ) = Σ_i ℓ_i(q_i(θ)).

Why a window. One image update moves the arm and one camera's offsets, and the bank
keeps each joint's marginal only, so the cameras each settle on a pose that explains
their own view of an arm that is a little off, along directions a single view cannot
tell apart. Images of two cameras at once do tell them apart: on the two-camera presets
L peaks at the true offsets (within 1-2 mm and 0.1 deg) while the tracker's estimate
sits thousands of nats below, on a shallow ridge (``docs/evaluation.md``, "Two
cameras"). L is not smooth in θ (rendered depth, pixels), so it is maximised by CMA-ES
(the ``cma`` package), from the tracker's own estimate, with the spreads ``scale``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

#: Scores (P, n) configurations: (P,) log-likelihoods of one image.
ImageScore = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class WindowImage:
    """One image of the window: its camera, the robot joints' readings at its capture
    time (the encoders' order) and its log-likelihood."""

    camera: str
    reading: np.ndarray
    score: ImageScore


@dataclass(frozen=True)
class WindowLayout:
    """Where θ goes in a configuration of the model's ``num_joints`` joints.

    ``robot_indices`` (m,): the robot joints (the readings' order) among them;
    ``bias_joints``: indices into the readings of the joints whose bias is fitted;
    ``camera_joints``: each camera's six virtual joints, in θ's order of cameras."""

    num_joints: int
    robot_indices: np.ndarray
    bias_joints: np.ndarray
    camera_joints: dict[str, np.ndarray]

    @property
    def size(self) -> int:
        """The length of θ."""
        return len(self.bias_joints) + 6 * len(self.camera_joints)

    def offsets(self, theta: np.ndarray, camera: str) -> np.ndarray:
        """(6,) camera ``camera``'s offsets in θ."""
        k = list(self.camera_joints).index(camera)
        start = len(self.bias_joints) + 6 * k
        return np.asarray(theta)[..., start:start + 6]

    def configurations(self, theta: np.ndarray, reading: np.ndarray,
                       camera: str | None = None) -> np.ndarray:
        """(P, n) the configurations q(θ) at robot ``reading`` for P rows of θ (P, size):
        camera ``camera``'s offsets set (None: every camera's), any other camera's 0."""
        theta = np.atleast_2d(theta)
        q = np.zeros((len(theta), self.num_joints))
        angles = np.broadcast_to(reading, (len(theta), len(reading))).copy()
        angles[:, self.bias_joints] -= theta[:, :len(self.bias_joints)]
        q[:, self.robot_indices] = angles
        for name in self.camera_joints if camera is None else (camera,):
            q[:, self.camera_joints[name]] = self.offsets(theta, name)
        return q


@dataclass(frozen=True)
class WindowFit:
    """The fit: θ at its start and at the maximum found, L at both, L's evaluations."""

    layout: WindowLayout
    theta_start: np.ndarray
    theta: np.ndarray
    log_likelihood_start: float
    log_likelihood: float
    evaluations: int

    def offsets(self, camera: str) -> np.ndarray:
        """(6,) camera ``camera``'s fitted offsets (x, y, z in m; rx, ry, rz in rad)."""
        return self.layout.offsets(self.theta, camera).copy()

    @property
    def biases(self) -> np.ndarray:
        """The fitted biases of ``layout.bias_joints`` (rad)."""
        return self.theta[:len(self.layout.bias_joints)].copy()


def window_log_likelihood(layout: WindowLayout, images: Sequence[WindowImage],
                          theta: np.ndarray) -> np.ndarray:
    """(P,) L(θ) for P rows of θ (P, size): the sum over ``images`` of each one's
    log-likelihood at its configuration."""
    theta = np.atleast_2d(np.asarray(theta, float))
    total = np.zeros(len(theta))
    for image in images:
        total += image.score(layout.configurations(theta, image.reading, image.camera))
    return total


def fit_window(layout: WindowLayout, images: Sequence[WindowImage], theta_start: np.ndarray,
               scale: np.ndarray, *, evaluations: int = 8000, seed: int = 0) -> WindowFit:
    """The θ that maximises L (see the module) found by CMA-ES from ``theta_start``, with
    initial spreads ``scale`` (one per entry of θ) and at most ``evaluations`` of L.

    Raises ValueError for no image, an image of a camera the layout does not have, a
    reading of the wrong length, or a non-finite or wrongly sized start or scale."""
    import cma  # a core dependency; imported here so the tracker's start never pays it

    theta_start = np.asarray(theta_start, float)
    scale = np.asarray(scale, float)
    _check(layout, images, theta_start, scale, evaluations)
    options = {"CMA_stds": scale, "maxfevals": int(evaluations), "verbose": -9,
               "seed": int(seed) + 1, "popsize": 24}
    search = cma.CMAEvolutionStrategy(np.zeros_like(theta_start), 1.0, options)
    start = float(window_log_likelihood(layout, images, theta_start)[0])
    best, best_value, count = theta_start, start, 1
    while not search.stop():
        steps = np.asarray(search.ask())
        values = window_log_likelihood(layout, images, theta_start + steps)
        count += len(steps)
        search.tell(list(steps), list(-values))  # CMA-ES minimises
        k = int(np.argmax(values))
        if values[k] > best_value:
            best, best_value = theta_start + steps[k], float(values[k])
    return WindowFit(layout, theta_start, np.array(best), start, best_value, count)


def _check(layout: WindowLayout, images: Sequence[WindowImage], theta_start: np.ndarray,
           scale: np.ndarray, evaluations: int) -> None:
    if not images:
        raise ValueError("fit_window: no image in the window")
    unknown = sorted({im.camera for im in images} - set(layout.camera_joints))
    if unknown:
        raise ValueError(f"fit_window: images of cameras {unknown}, not among the "
                         f"layout's {list(layout.camera_joints)}")
    m = len(layout.robot_indices)
    for im in images:
        if np.shape(im.reading) != (m,) or not np.all(np.isfinite(im.reading)):
            raise ValueError(f"fit_window: an image of '{im.camera}' has readings "
                             f"{np.shape(im.reading)} (need {m} finite values)")
    for name, value in (("theta_start", theta_start), ("scale", scale)):
        if value.shape != (layout.size,) or not np.all(np.isfinite(value)):
            raise ValueError(f"fit_window: {name} must be {layout.size} finite values, got "
                             f"shape {value.shape}")
    if np.any(scale <= 0):
        raise ValueError("fit_window: every scale must be > 0")
    if evaluations < 100:
        raise ValueError(f"fit_window: evaluations must be >= 100, got {evaluations}")
