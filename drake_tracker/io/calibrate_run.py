"""``drake-tracker calibrate-cameras``: each camera's mounting error, from a recording of
several cameras: a recorded run, a bag or an LCM log, as events (``io/stream.py``).
``core/calibration/window_fit.py`` has the fit and why it is needed.

The tracker replays the recording to the end of the window; its estimate there (every robot
joint's bias and each camera's offsets) starts the fit. The window's images, at most
``images_per_camera`` of each camera spread evenly over it, are scored by that tracker's
own image updates. The joints that move a camera (a pan-tilt head) are fitted with the
rest, then folded into that camera's offsets at their mean reading over the window: a
constant error of a head joint and a mounting error are one rigid transform there. The
result is a ``TrackerParams`` fragment for every later run of the same cell
(``--params``): ``camera_offsets``, held (``estimate_camera_offset: false``).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.calibration.calibration_params import SelfCalibrationParams
from drake_tracker.core.calibration.fold import (
    belief_theta,
    calibration_layout,
    camera_only_joints,
    fit_cameras,
)
from drake_tracker.core.calibration.online import (
    found_window,
    image_scorer,
    shows_the_arm,
)
from drake_tracker.core.calibration.window_fit import WindowFit, WindowImage, WindowLayout
from drake_tracker.core.robustness.health import HealthState
from drake_tracker.core.sensors.depth_frames import in_metres
from drake_tracker.params.resolve import joint_noise_for
from drake_tracker.params.tracker_params import JointNoise, TrackerParams

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.io.stream import Event
    from drake_tracker.robot.model import TrackerModel

#: The window's length when it is found (s): two seconds of every camera seeing the arm
#: (the tracker's own calibration waits for one, ``camera_calibration.window_s``).
WINDOW_S = 2.0

_ONE_CAMERA = ("calibrate-cameras needs several cameras: with one, the arm's biases and "
               "the camera's offsets explain its view together")


@dataclass(frozen=True)
class CameraCalibration:
    """Each camera's calibrated offsets (x, y, z in m; rx, ry, rz in rad), the fit, and
    the images it used per camera."""

    offsets: dict[str, np.ndarray]
    fit: WindowFit
    window_s: tuple[float, float]
    images: dict[str, int]
    #: The joints that move a camera and not the hand (a pan-tilt head), each with its
    #: noise model as the fit's parameters had it, trusted from now on (``has_bias``
    #: false): their constant error is in the offsets.
    trusted: dict[str, JointNoise] = field(default_factory=dict)

    def params_yaml(self) -> str:
        """The ``TrackerParams`` fragment: ``camera_offsets``, held
        (``estimate_camera_offset: false``; true lets the images move them again), and
        the joints that move only cameras trusted (``kalman.overrides``)."""
        lines = [f"# drake-tracker calibrate-cameras: window {self.window_s[0]:g}-"
                 f"{self.window_s[1]:g} s, images {self.images}, log-likelihood "
                 f"{self.fit.log_likelihood_start:.0f} -> {self.fit.log_likelihood:.0f}",
                 "estimate_camera_offset: false",
                 "camera_offsets:"]
        for name, o in self.offsets.items():
            lines.append(f"  {name}: [{', '.join(f'{v:.6g}' for v in o)}]")
        if self.trusted:
            lines += ["kalman:", "  overrides:"]
            for name, noise in self.trusted.items():
                fields = ", ".join(f"{k}: {str(v).lower() if isinstance(v, bool) else repr(v)}"
                                   for k, v in asdict(noise).items())
                lines.append(f"    {name}: {{{fields}}}")
        return "\n".join(lines) + "\n"


def calibrate_run(run: RecordedRun, params: TrackerParams | None = None, *,
                  start_s: float | None = None, end_s: float | None = None,
                  window_s: float = WINDOW_S, images_per_camera: int = 10,
                  evaluations: int = 8000, seed: int = 0,
                  model: TrackerModel | None = None) -> CameraCalibration:
    """:func:`calibrate_cameras` on a recorded run of several cameras."""
    from drake_tracker.io.replay import model_for_run
    from drake_tracker.io.track_files import run_events

    if not run.other_cameras:
        raise ValueError(_ONE_CAMERA)
    model = model if model is not None else model_for_run(run)
    return calibrate_cameras(run_events(run), model, run.intrinsics_by_camera, params,
                             start_s=start_s, end_s=end_s, window_s=window_s,
                             images_per_camera=images_per_camera, evaluations=evaluations,
                             seed=seed)


def calibrate_cameras(events: Iterable[Event], model: TrackerModel, cameras: dict,
                      params: TrackerParams | None = None, *, start_s: float | None = None,
                      end_s: float | None = None, window_s: float = WINDOW_S,
                      images_per_camera: int = 10, evaluations: int = 8000,
                      seed: int = 0) -> CameraCalibration:
    """Fits every camera's offsets to the images captured in a window of ``events`` (a
    recorded run's, a bag's, a log's: ``io/stream.py``); ``cameras`` is each camera's
    intrinsics by name (see the module). The window is [start_s, end_s], or without them
    the first ``window_s`` seconds, after every camera has said ``tracking``, in which
    at least 3 images of each camera show the arm where the tracker puts it (at least
    ``health.min_robot_pixels`` unhidden, at most half hidden: ``shows_the_arm``); the
    fit takes those images.
    ValueError for fewer than two cameras, no such window, a camera without an image in
    it or one that sees no arm there."""
    if len(cameras) < 2:
        raise ValueError(_ONE_CAMERA)
    if (start_s is None) != (end_s is None):
        raise ValueError("give the window's start and end together, or neither (the first "
                         f"{window_s:g} s in which every camera sees the arm)")
    if start_s is not None and not (0.0 <= start_s < end_s):
        raise ValueError(f"the window must have 0 <= start < end, got {start_s}-{end_s} s")
    if not (np.isfinite(window_s) and window_s > 0):
        raise ValueError(f"the window's length must be > 0 s, got {window_s}")
    # The replay finds the window itself: it does not calibrate online as well.
    params = replace(params if params is not None else TrackerParams())
    params.camera_calibration = SelfCalibrationParams(window_s=0.0)
    window = _Window(start_s, end_s, window_s)
    tracker = _replayed(window, events, model, cameras, params)
    start_s, end_s = window.start_s, window.end_s
    layout = calibration_layout(model, tracker.params)
    images, seen = [], {}
    offset_s = tracker.params.image.image_time_offset_s
    for name in model.camera_names:
        mine = window.images.get(name, [])
        if not mine:
            raise ValueError(f"camera '{name}' has no image in {start_s}-{end_s} s")
        chosen = [mine[k] for k in np.unique(np.linspace(0, len(mine) - 1,
                                                         images_per_camera).round().astype(int))]
        seen[name] = len(chosen)
        update = tracker.channel(name).images.update
        for capture_s, depth in chosen:
            observation = update.prepare(depth)
            images.append(WindowImage(name, window.reading_at(capture_s - offset_s),
                                      image_scorer(update, observation)))
    _, belief = tracker.buffer.present()
    _require_views(tracker, layout, images, belief_theta(model, layout, belief),
                   tracker.params.health.min_robot_pixels)
    mean_reading = np.mean([window.reading_at(t) for t in np.linspace(start_s, end_s, 21)],
                           axis=0)
    offsets, fit = fit_cameras(model, tracker.params, images, belief, mean_reading,
                               evaluations=evaluations, seed=seed)
    names = camera_only_joints(model)
    noise = joint_noise_for(params, list(model.joint_names), model.prismatic_joint_names,
                            model.virtual_joint_names)
    trusted = {n: replace(noise[model.joint_names.index(n)], has_bias=False) for n in names}
    return CameraCalibration(offsets, fit, (start_s, end_s), seen, trusted)


class _Window:
    """What a stream shows of the window: every reading up to its end and each camera's
    images captured in it that the tracker took (depth in metres); without given
    bounds, which of them showed the arm (``seen``), until every camera's did for
    ``length_s``."""

    def __init__(self, start_s: float | None, end_s: float | None, length_s: float):
        self.start_s, self.end_s, self.length_s = start_s, end_s, length_s
        self.reading_times: list[float] = []
        self.readings: list[np.ndarray] = []
        self.images: dict[str, list[tuple[float, np.ndarray]]] = {}
        self.cameras: dict[tuple[float, int], str] = {}  # (capture, sequence) -> camera
        self.seen: dict[str, list[tuple[float, bool]]] = {}
        self.tracking_since: dict[str, float] = {}

    @property
    def given(self) -> bool:
        return self.end_s is not None

    def collect(self, events: Iterable[Event]) -> Iterator[Event]:
        """``events`` as they are, their readings kept; a given window's images kept
        (captured in it, whenever they arrive), the others' cameras noted for
        :meth:`took`."""
        from drake_tracker.io.stream import ImageEvent, ReadingEvent

        for event in events:
            if isinstance(event, ReadingEvent) and np.all(np.isfinite(event.positions)):
                self.reading_times.append(event.time_s)
                self.readings.append(np.asarray(event.positions, float))
            elif isinstance(event, ImageEvent) and event.camera is not None:
                if not self.given:
                    self.cameras[(float(event.capture_s), int(event.sequence))] = event.camera
                elif self.start_s <= event.capture_s <= self.end_s:
                    self.images.setdefault(event.camera, []).append(
                        (event.capture_s, in_metres(event.depth)))
            yield event

    def took(self, tracker, frame, min_pixels: int) -> None:
        """Without given bounds, after the tracker took ``frame`` (``track_stream``'s
        ``on_image``): the image kept while a window ending now could need it, and
        whether its camera's latest image showed the arm. Ends the replay
        (``_WindowFoundError``) at the first time 3 images of every camera did within
        ``length_s`` (``found_window``), counted from when every camera had said
        ``tracking`` (the estimate that starts the fit holds the arm)."""
        t = float(frame.capture_time_s)
        camera = self.cameras.pop((t, int(frame.sequence)), None)
        if camera is None:
            return
        mine = self.images.setdefault(camera, [])
        health = tracker.channel(camera).health
        shown = shows_the_arm(health, min_pixels)
        if shown:
            mine.append((t, in_metres(frame.depth_m)))
        while mine and mine[0][0] < t - self.length_s - 1.0:
            mine.pop(0)
        self.seen.setdefault(camera, []).append((t, shown))
        if health.state == HealthState.TRACKING:
            self.tracking_since.setdefault(camera, t)
        start = found_window(self.seen, self.tracking_since, list(tracker.channels), t,
                             self.length_s)
        if start is None:
            return
        self.start_s, self.end_s = start, t
        self.images = {name: [(s, d) for s, d in images if start <= s <= t]
                       for name, images in self.images.items()}
        raise _WindowFoundError

    def reading_at(self, t: float) -> np.ndarray:
        """The latest reading stamped at or before ``t`` (the first one before it)."""
        k = int(np.searchsorted(self.reading_times, t + 1e-9, side="right")) - 1
        return self.readings[max(k, 0)]


class _WindowFoundError(Exception):
    """Ends the replay at the end of the window found."""


def _replayed(window: _Window, events: Iterable[Event], model: TrackerModel,
              cameras: dict, params: TrackerParams):
    """A tracker fed the stream to the window's end (given: every event that arrived by
    it; found: until it is found), the window's images kept as the tracker took them."""
    from drake_tracker.io.stream import ImageEvent, ReadingEvent, track_stream
    from drake_tracker.tracker import Tracker

    tracker = Tracker(model, params=params, cameras=cameras)
    min_pixels = tracker.params.health.min_robot_pixels
    stream = window.collect(events)
    if window.given:
        end_s = window.end_s

        def arrived(event) -> bool:
            if isinstance(event, ReadingEvent):
                return event.time_s <= end_s
            if isinstance(event, ImageEvent):
                return (event.capture_s if event.arrival_s is None
                        else event.arrival_s) <= end_s
            return True

        stream = (e for e in itertools.takewhile(lambda e: _before(e, end_s + 1.0), stream)
                  if arrived(e))
    try:
        track_stream(stream, tracker,
                     on_image=lambda trk, frame: window.took(trk, frame, min_pixels))
    except _WindowFoundError:
        return tracker
    if window.given:
        if not tracker.started:
            raise ValueError(f"no joint reading by {end_s} s: the tracker did not start")
        return tracker
    raise ValueError(f"no {window.length_s:g} s in which 3 images of every camera show "
                     f"the arm (at least {min_pixels} pixels unhidden where the tracker "
                     f"puts it): give the window (--from, --to)")


def _before(event, limit_s: float) -> bool:
    """Whether the stream (in arrival order) has not yet passed ``limit_s``: a bag or
    log is not read to its end for a window at its start."""
    from drake_tracker.io.stream import ReadingEvent

    return not (isinstance(event, ReadingEvent) and event.time_s > limit_s)


def _require_views(tracker, layout: WindowLayout, images: list[WindowImage],
                   theta: np.ndarray, min_pixels: int) -> None:
    """ValueError when a camera renders fewer than ``min_pixels`` of the arm, at the
    tracker's estimate, in every one of its window images: the fit could not place it."""
    for camera in layout.camera_joints:
        renderer = tracker.channel(camera).images.update.renderer
        shown = [int(np.sum(np.isfinite(renderer.render(
            layout.configurations(theta, im.reading, camera))[0])))
            for im in images if im.camera == camera]
        if max(shown) < min_pixels:
            raise ValueError(f"camera '{camera}' sees at most {max(shown)} pixels of the arm "
                             f"in the window's images (fewer than {min_pixels}): choose a "
                             f"window in which every camera sees the arm")
