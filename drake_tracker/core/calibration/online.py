"""The tracker calibrates its cameras itself, once, while it runs (several cameras).

Why. One image update moves the arm and one camera's offsets, and the bank keeps each
joint's marginal only: the cameras settle on poses that explain their own views of an
arm a little off, on a ridge of the likelihood of both cameras' images that the updates
do not climb (``window_fit``). Measured on in-out-in-2cam/constant seed 0, the hand in
the head camera's frame was then 6-12 mm off while that camera could not see it. A fit
of the window's images of every camera at once climbs it (0.7-2.2 mm); put into the
running filter it was lost within 0.5 s (the next one-camera updates walked it off),
held it stays (``docs/evaluation.md``, "Two cameras").

What. :class:`SelfCalibration` watches every image the tracker takes. The first
``camera_calibration.window_s`` seconds (1 s) after every camera said ``tracking`` in which
each camera has at least 3 images that show the arm (:func:`shows_the_arm`) is the
window, as ``drake-tracker calibrate-cameras`` finds it; the image that completes it
runs the fit (``fold.fit_cameras``: 10 images of each camera,
``camera_calibration.max_evaluations`` evaluations, a few seconds of that one image's
time). From then on :class:`HeldCameras` holds what the fit found: each camera's six
offsets, and the joints that move only cameras (a pan-tilt head) trusted at their
readings (their constant error folded into the offsets). The image updates no longer
sample those joints, and each image's observation pins them (``HeldCameras.pin``): a
restart keeps them too.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.calibration.fold import camera_only_joints, fit_cameras
from drake_tracker.core.calibration.window_fit import WindowImage
from drake_tracker.core.filter.angle_observation import AngleObservation, Restart
from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B
from drake_tracker.core.robustness.health import HealthState

if TYPE_CHECKING:
    from drake_tracker.core.cpf.image_update import CpfImageUpdate
    from drake_tracker.core.likelihood.pixel_model import PreparedObservation
    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.core.robustness.health import TrackerHealth
    from drake_tracker.robot.model import TrackerModel

#: Images of each camera in the fit, spread over the window (``calibrate-cameras``
#: measured, with 8,000 evaluations: 4-13 s per fit on a Zen 4 core, each mount within
#: 2 mm and 0.14 deg on ten calibrations).
IMAGES_PER_CAMERA = 10
#: The standard deviation of a held joint's pin (rad or m): far below anything an image
#: or a reading resolves, far above float64's resolution of a precision's information.
PIN_STD = 1e-6


def found_window(seen: dict[str, list[tuple[float, bool]]], tracking_since: dict[str, float],
                 cameras: list[str], t: float, length_s: float) -> float | None:
    """The start of the window ending at ``t``, or None: every camera of ``cameras`` has
    said ``tracking`` (``tracking_since``: when it first did) by ``t - length_s``, and
    at least 3 of each camera's images since then showed the arm (``seen``: (capture
    time, whether it did)); the fit takes those, not the others. Measured: requiring
    every image to show it, the quick suite's occlusion-lasting-2cam (10 s, the head
    camera's view of the arm mostly behind the plate) found no window, 7.1 / 9.4 mm in
    the head camera's frame over the whole run; with this rule 2.8 / 4.1 mm, the runs
    at the presets' own length byte for byte the same."""
    if any(name not in tracking_since for name in cameras):
        return None
    start = t - length_s
    if start < max(tracking_since[name] for name in cameras):
        return None
    for name in cameras:
        inside = [ok for s, ok in seen.get(name, []) if start <= s <= t]
        if sum(inside) < 3:
            return None
    return start


@dataclass(frozen=True)
class HeldCameras:
    """The cameras' poses held once calibrated: ``offsets`` (n,) every camera's six
    offsets on its virtual joints (NaN elsewhere); ``trusted`` (n,) bool, the joints
    that move only cameras, held at their readings (bias 0). ``window_s`` and
    ``log_likelihood`` (the tracker's estimate's, then the fit's) say where it came
    from; the fit took ``evaluations`` and ``fit_wall_s``."""

    offsets: np.ndarray
    trusted: np.ndarray
    window_s: tuple[float, float]
    log_likelihood: tuple[float, float]
    #: The fit's evaluations of the window's log-likelihood, and its wall time (s).
    evaluations: int = 0
    fit_wall_s: float = 0.0

    @property
    def held(self) -> np.ndarray:
        """(n,) bool: the joints the images no longer move."""
        return np.isfinite(self.offsets) | self.trusted

    def targets(self, prior: np.ndarray) -> np.ndarray:
        """(n,) each held joint's angle at ``prior`` (5, n): its offset, or its reading
        ``a + b`` for a trusted joint (NaN for the others)."""
        out = self.offsets.copy()
        out[self.trusted] = prior[MEAN_A, self.trusted] + prior[MEAN_B, self.trusted]
        return out

    def prior(self, prior: np.ndarray) -> np.ndarray:
        """``prior`` with each held joint's angle at its target (its ``a + b`` kept)."""
        out = np.array(prior, float, copy=True)
        held, target = self.held, self.targets(prior)
        out[MEAN_B, held] = prior[MEAN_A, held] + prior[MEAN_B, held] - target[held]
        out[MEAN_A, held] = target[held]
        return out

    def blocks(self, blocks: Sequence[np.ndarray]) -> list[np.ndarray]:
        """The CPF ``blocks`` without the held joints (an emptied block dropped)."""
        held = self.held
        kept = [np.asarray(b)[~held[np.asarray(b)]] for b in blocks]
        return [b for b in kept if len(b)]

    def restart(self, restart: Restart) -> Restart:
        """``restart`` that returns the offsets to the calibration, not to 0 (a kept
        restart keeps them as they are)."""
        if restart.keep_bias:
            return restart
        pinned = (np.full(len(self.offsets), np.nan) if restart.pinned_angle is None
                  else np.array(restart.pinned_angle, float, copy=True))
        mine = np.isfinite(self.offsets)
        pinned[mine] = self.offsets[mine]
        return replace(restart, pinned_angle=pinned)

    def pin(self, observation: AngleObservation, prior: np.ndarray) -> AngleObservation:
        """``observation`` (relative to ``prior``) that also sets each held joint to its
        target within ``PIN_STD``, its restart (if any) returning there."""
        held, target = self.held, self.targets(prior)
        precision = np.array(observation.precision, float, copy=True)
        information = np.array(observation.information, float, copy=True)
        precision[held] = PIN_STD ** -2
        information[held] = target[held] * PIN_STD ** -2
        restart = None if observation.restart is None else self.restart(observation.restart)
        return AngleObservation(precision, information, restart)


@dataclass(frozen=True)
class SelfCalibration:
    """What the tracker has seen of the window (frozen: :meth:`took` returns the next
    state), and what it holds once calibrated (``held``)."""

    #: (camera, capture time, prepared image, robot reading) of the images that may
    #: still fall in the window.
    images: tuple = ()
    #: camera -> ((capture time, whether its image showed the arm), ...).
    seen: tuple = ()
    #: (camera, when it first said ``tracking``) of each camera.
    tracking_since: tuple = ()
    held: HeldCameras | None = None

    def took(self, camera: str, t: float, depth_m: np.ndarray | None, prior: np.ndarray,
             health: TrackerHealth, update: CpfImageUpdate,
             min_pixels: int, window_s: float) -> SelfCalibration:
        """The state after camera ``camera``'s image at ``t`` (its depth, the prior at
        its time, its camera's ``health`` after it; ``update`` its camera's image
        update). Once calibrated, nothing changes."""
        if self.held is not None:
            return self
        shown = depth_m is not None and shows_the_arm(health, min_pixels)
        since = dict(self.tracking_since)
        if health.state == HealthState.TRACKING:
            since.setdefault(camera, t)
        keep_s = t - window_s - 1.0
        seen = {name: [(s, ok) for s, ok in marks if s >= keep_s] for name, marks in self.seen}
        seen.setdefault(camera, []).append((t, shown))
        images = [im for im in self.images if im[1] >= keep_s]
        if shown:
            robot = robot_reading(prior, update)
            images.append((camera, t, update.prepare(depth_m), robot))
        return SelfCalibration(tuple(images), tuple((n, tuple(m)) for n, m in seen.items()),
                               tuple(since.items()))

    def window(self, t: float, cameras: list[str], window_s: float) -> float | None:
        """The start of the window of ``window_s``, if it ends at ``t``."""
        return found_window({n: list(m) for n, m in self.seen}, dict(self.tracking_since),
                            cameras, t, window_s)

    def calibrated(self, model: TrackerModel, params: ResolvedParams,
                   updates: dict[str, CpfImageUpdate], prior: np.ndarray, start_s: float,
                   end_s: float) -> SelfCalibration:
        """The state holding the fit of the window [start_s, end_s] from ``prior``
        (``updates``: each camera's image update, which scores its images)."""
        images, readings = [], []
        for name in model.camera_names:
            mine = [im for im in self.images if im[0] == name and start_s <= im[1] <= end_s]
            picks = np.unique(np.linspace(0, len(mine) - 1, IMAGES_PER_CAMERA).round())
            for k in picks.astype(int):
                _, _, observation, reading = mine[k]
                update = updates[name]
                images.append(WindowImage(name, reading, image_scorer(update, observation)))
                readings.append(reading)
        started = time.perf_counter()
        offsets, fit = fit_cameras(model, params, images, prior, np.mean(readings, axis=0),
                                   evaluations=params.camera_calibration.max_evaluations,
                                   seed=params.image.seed)
        n = model.num_joints
        held_offsets = np.full(n, np.nan)
        for name, o in offsets.items():
            held_offsets[model.camera_joint_indices(name)] = o
        trusted = np.zeros(n, bool)
        trusted[[model.joint_names.index(j) for j in camera_only_joints(model)]] = True
        held = HeldCameras(held_offsets, trusted, (start_s, end_s),
                           (fit.log_likelihood_start, fit.log_likelihood), fit.evaluations,
                           time.perf_counter() - started)
        return SelfCalibration(held=held)


def self_calibration(params: ResolvedParams, model: TrackerModel,
                     cameras: list[str]) -> SelfCalibration | None:
    """The calibration's first state for a tracker whose image updates take ``cameras``
    (the model's camera names, in its order), or None when it does not calibrate: the
    parameters say no (``ResolvedParams.camera_calibration``), or a camera of the model
    has no image update (the fit needs every camera's images)."""
    if params.camera_calibration is None or list(cameras) != model.camera_names:
        return None
    return SelfCalibration()


def shows_the_arm(health: TrackerHealth, min_pixels: int) -> bool:
    """Whether the image behind ``health.latest`` shows the arm for the window: at least
    ``min_pixels`` of it unhidden where the tracker puts it, and no more of it hidden
    than unhidden (``ImageConsistency.mostly_hidden``, a vote: the rule by which an
    image of one of several cameras is applied while another tracks, in
    ``ImageProcessor``; it replaces a constant, ``MAX_HIDDEN_FRACTION`` 0.5). Measured:
    with unhidden pixels alone, on occlusion-lasting-2cam/constant seed 4 (quick suite,
    a 1 s window) the head camera's images of 8.45-9.45 s, 93-97 % hidden behind the
    plate, made the window, and the fit turned that camera 26 deg (the hand 526 mm off
    in its frame)."""
    latest = health.latest
    return (latest is not None and latest.visible_robot_pixels >= min_pixels
            and not latest.mostly_hidden)


def robot_reading(prior: np.ndarray, update: CpfImageUpdate) -> np.ndarray:
    """The robot joints' readings (the encoders' order) at ``prior``: ``a + b``."""
    robot = np.asarray(update.model.robot_joint_indices)
    return prior[MEAN_A, robot] + prior[MEAN_B, robot]


def image_scorer(update: CpfImageUpdate, observation: PreparedObservation
                 ) -> Callable[[np.ndarray], np.ndarray]:
    """``WindowImage``'s score: the log-likelihood of ``observation`` (prepared by
    ``update``) at configurations q, by its camera's image update."""
    return lambda q: update.log_likelihood(q, observation)
