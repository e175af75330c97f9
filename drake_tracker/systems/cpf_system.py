"""The Coordinate Particle Filter image update as a Drake LeafSystem."""

from __future__ import annotations

import logging
from concurrent.futures import Future
from dataclasses import replace
from typing import TYPE_CHECKING

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import Context, EventStatus, InputPort, LeafSystem, OutputPort

from drake_tracker.core.calibration.online import self_calibration
from drake_tracker.core.cameras import (
    another_camera_tracks,
    camera_named,
    clock_disagreement,
)
from drake_tracker.core.image_processor import ImageProcessor
from drake_tracker.core.image_step import calibrate_after, conclude_image
from drake_tracker.core.robustness.health import TrackerHealth
from drake_tracker.core.sensors.camera import CameraIntrinsics, as_intrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.core.sensors.timestamps import problem_kind
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.systems.cpf_state import CameraImageState, CpfState, ImageUpdateInFlight
from drake_tracker.systems.delay_buffer_system import camera_port_names, frame_key
from drake_tracker.systems.image_update_worker import DeadlineWaits, submit_image_update
from drake_tracker.systems.messages import ImageObservationMessage, ImagePrior

if TYPE_CHECKING:
    from pydrake.systems.sensors import CameraInfo

    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)


class CpfImageUpdateSystem(LeafSystem):
    """Runs the CPF image update once per new depth image (a periodic unrestricted update
    that compares the image's sequence number and capture stamp with the last frame's,
    since Python systems cannot schedule their own next update time; a sequence counter
    that restarts is logged once per restart).

    .. pydrake_system::

        name: CpfImageUpdateSystem
        input_ports:
        - depth_frame
        - image_prior
        output_ports:
        - image_observation
        - health

    ``depth_frame`` carries a :class:`DepthFrame` (full resolution of ``camera``);
    ``image_prior`` where the delay buffer places that frame, with the angles' prior at
    its time. ``image_observation`` is an :class:`ImageObservationMessage` whose id grows
    by one per applied image; ``health`` the :class:`TrackerHealth` after it. The random
    numbers of image ``k`` depend only on (``image.seed``, k). Malformed images, images
    the buffer cannot place and failed updates are skipped with a rate-limited warning.

    With ``image.update_latency_s`` L > 0 the update runs on the image-update thread
    (``image_update_worker``) while the simulation goes on, and its message appears at the
    first check L after the image was taken up (the Simulator waits there if the thread
    is not done: ``deadline_waits`` counts how often, and how long), the same message
    as with L = 0. A due image that comes while an update
    is in flight applies that one first; an image is taken up only once its prior holds
    every applied update (``ImagePrior.observation_id``). ``state(context).in_flight``
    is the running update.

    With ``cameras`` (name -> camera model, each of the model's cameras) each camera has
    its own ``<name>_depth_frame`` and ``<name>_image_prior`` inputs and
    ``<name>_health`` output, and its own image update (rendered through its own
    estimated frame, ``ImageProcessor(camera_name=...)``), pacing and health; the
    frames new at a check are taken in their arrival order (the camera order on a tie),
    one update at a time, as the offline ``Tracker`` takes them. ``health`` is that of
    the camera in the best state. An image whose camera's clock disagrees with another
    camera's by more than the buffer horizon is skipped, warned and counted.
    """

    def __init__(self, *, model: TrackerModel,
                 camera: CameraIntrinsics | CameraInfo | None = None,
                 params: TrackerParams | ResolvedParams, period_s: float,
                 offset_s: float = 0.0,
                 cameras: dict[str, CameraIntrinsics | CameraInfo] | None = None) -> None:
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"CpfImageUpdateSystem: period_s must be > 0, got {period_s}")
        if (camera is None) == (cameras is None):
            raise ValueError("CpfImageUpdateSystem: give either camera= (the model's first "
                             "camera) or cameras={name: camera model}, one of the two")
        prefixes = camera_port_names(model, None if cameras is None else list(cameras))
        models = {model.camera_names[0]: camera} if cameras is None else cameras
        self._params = params = resolve_tracker_params(params, model)
        #: Each camera's image update (its own estimated frame and virtual joints).
        self.processors = {name: ImageProcessor(model, as_intrinsics(models[name]), params,
                                                camera_name=name) for name in prefixes}
        #: The first camera's image update (with one camera, the only one).
        self.processor = next(iter(self.processors.values()))
        self._period_s = float(period_s)
        self._latency_s = float(params.image.update_latency_s)
        self._several = len(prefixes) > 1
        #: Updates on the worker done at their deadline or late (a diagnostic).
        self.deadline_waits = DeadlineWaits()
        #: The images skipped with a warning, counted by kind (a diagnostic over all its
        #: Contexts, as ``deadline_waits``).
        self.warnings = RateLimitedWarning(log)
        self._model = model
        self._state = self.DeclareAbstractState(AbstractValue.Make(CpfState(
            cameras={name: CameraImageState(name) for name in prefixes},
            calibration=self_calibration(params, model, list(prefixes)))))
        self._frame_ports = {name: self.DeclareAbstractInputPort(
            f"{prefix}depth_frame", AbstractValue.Make(DepthFrame.empty()))
            for name, prefix in prefixes.items()}
        self._prior_ports = {name: self.DeclareAbstractInputPort(
            f"{prefix}image_prior", AbstractValue.Make(ImagePrior()))
            for name, prefix in prefixes.items()}
        state_ticket = {self.abstract_state_ticket(self._state)}
        self._message_port = self.DeclareAbstractOutputPort(
            "image_observation", lambda: AbstractValue.Make(ImageObservationMessage()),
            lambda c, o: o.set_value(self.state(c).message), state_ticket)
        self._health_port = self.DeclareAbstractOutputPort(
            "health", lambda: AbstractValue.Make(TrackerHealth()),
            lambda c, o: o.set_value(self.state(c).health), state_ticket)
        self._camera_health_ports = {name: self.DeclareAbstractOutputPort(
            f"{prefix}health", lambda: AbstractValue.Make(TrackerHealth()),
            lambda c, o, name=name: o.set_value(self.state(c).cameras[name].health),
            state_ticket) for name, prefix in prefixes.items() if prefix}
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._update)

    @property
    def camera_names(self) -> list[str]:
        """The cameras whose images the system takes, in the model's order."""
        return list(self._frame_ports)

    def _camera(self, camera: str | None) -> str:
        return camera_named(camera, self.camera_names, "system")

    def get_depth_frame_input_port(self, camera: str | None = None) -> InputPort:
        """The ``depth_frame`` input port of ``camera`` (None: the only camera)."""
        return self._frame_ports[self._camera(camera)]

    def get_image_prior_input_port(self, camera: str | None = None) -> InputPort:
        """The ``image_prior`` input port of ``camera`` (None: the only camera)."""
        return self._prior_ports[self._camera(camera)]

    def get_image_observation_output_port(self) -> OutputPort:
        """The ``image_observation`` output port."""
        return self._message_port

    def get_health_output_port(self, camera: str | None = None) -> OutputPort:
        """The ``health`` output port (the best camera's); with ``camera``, that camera's
        (``<name>_health``, with several cameras)."""
        if camera is None:
            return self._health_port
        name = self._camera(camera)
        return self._camera_health_ports.get(name, self._health_port)

    def state(self, context: Context) -> CpfState:
        """The system's state in ``context`` (counts, health, latest message)."""
        return context.get_abstract_state(self._state).get_value()

    def _new_frames(self, context: Context, s: CpfState) -> list[tuple[str, DepthFrame]]:
        """The cameras with a new frame on their port, in arrival order (camera order on
        a tie)."""
        frames = []
        for name, port in self._frame_ports.items():
            frame: DepthFrame = port.Eval(context)
            if not frame.is_empty and frame_key(frame) != s.cameras[name].last_frame:
                frames.append((name, frame))
        if len(frames) > 1:
            frames.sort(key=lambda item: item[1].arrival_time_s)  # stable: camera order
        return frames

    def _update(self, context, state) -> EventStatus | None:
        stored, now = self.state(context), context.get_time()
        frames = self._new_frames(context, stored)
        job = stored.in_flight
        result_due = job is not None and now >= job.due_s - 1e-9
        if not frames and not result_due:
            # No new frame and no result due (at 999 of 1000 checks): Drake keeps the
            # state as it is and recomputes nothing that depends on it.
            return EventStatus.DidNothing()
        s = stored.copy()
        s.cameras = dict(stored.cameras)
        if result_due:
            self._finish_in_flight(s)
        for name, frame in frames:
            self._take_frame(name, frame, self._prior_ports[name].Eval(context), s, now)
        state.get_mutable_abstract_state(self._state).set_value(s)

    def _take_frame(self, name: str, frame: DepthFrame, prior: ImagePrior, s: CpfState,
                    now: float) -> None:
        """A new frame of camera ``name``: the update in flight first if the frame may be
        due, then the frame itself, unless its prior lacks the latest update (put off for
        one check)."""
        if s.in_flight is not None and self._may_be_due(name, prior, s):
            self._finish_in_flight(s)
        key, cam = frame_key(frame), s.cameras[name]
        if prior.anchor is not None and prior.observation_id < s.message.id:
            if cam.deferred_frame != key:  # its prior lacks the latest update: look again
                s.cameras[name] = replace(cam, deferred_frame=key)
                return
            # still: the prior does not come from a buffer that takes them in
            self.warnings.warn("prior without the latest update", (
                f"image {frame.sequence}'s prior holds image updates up to "
                f"{prior.observation_id}, not {s.message.id}: is image_observation "
                f"connected to the buffer that sends image_prior? Used as it is"))
        if frame.sequence < cam.last_sequence:
            log.warning("camera sequence counter restarted: image %d after image %d; "
                        "frames are told apart by sequence and stamp", frame.sequence,
                        cam.last_sequence)
        elif cam.last_sequence >= 0 and frame.sequence - cam.last_sequence > 1:
            missed = frame.sequence - cam.last_sequence - 1
            s.images_skipped += missed
            self.warnings.warn("frames never seen", (
                f"{missed} frame(s) before image {frame.sequence}{self._of(name)} were "
                f"never on the depth port when it was checked (every "
                f"{self._period_s * 1e3:g} ms): dropped by the camera, or replaced by a "
                f"newer one between two checks"))
        s.cameras[name] = replace(cam, last_sequence=frame.sequence, last_frame=key)
        s.count(self._process(name, frame, prior, s, now))

    def _of(self, name: str) -> str:
        return f" of camera '{name}'" if self._several else ""

    def _finish_in_flight(self, s: CpfState) -> None:
        job, s.in_flight = s.in_flight, None
        s.count(self._finish(job.camera, job.frame, job.prior, job.outcome, s, job.search))

    def _may_be_due(self, name: str, prior: ImagePrior, s: CpfState) -> bool:
        """Whether camera ``name``'s new frame may be due once the update in flight is
        applied (then that one is applied first, as it would have been without the
        latency)."""
        if prior.anchor is None:
            return False
        pacing = s.cameras[name].pacing
        if s.in_flight.camera == name:
            pacing = pacing.applied(s.in_flight.prior.image_time_s)
        return pacing.wants(prior.image_time_s)

    def _process(self, name: str, frame: DepthFrame, prior: ImagePrior, s: CpfState,
                 now_s: float) -> bool | None:
        """Starts the image update of camera ``name`` on ``frame`` if it is due: None
        when it runs on the worker (``s.in_flight``); else whether it produced a new
        observation message."""
        t, cam = prior.image_time_s, s.cameras[name]
        if prior.sequence == frame.sequence and t == t:  # NaN: its stamp was rejected
            lag = frame.arrival_time_s - t
            problem = clock_disagreement(cam, s.cameras, lag, self._params.buffer_horizon_s)
            if problem:
                return self._skip(name, frame, problem, "images whose camera clock disagrees")
            if not cam.pacing.wants(t):
                return False  # not due
        if prior.anchor is None or prior.sequence != frame.sequence:
            return self._skip(name, frame, prior.problem)
        cam = replace(cam, pacing=cam.pacing.taken_up(t, self._params.image.min_image_interval_s),
                      lag_s=frame.arrival_time_s - t)
        s.cameras[name] = cam
        args = (frame, prior.anchor.prior, cam.pacing.jump_window_s(t, cam.health), cam.health,
                another_camera_tracks({n: c.health for n, c in s.cameras.items()}, name),
                None if s.calibration is None else s.calibration.held)
        observe = self.processors[name].observe
        if self._latency_s > 0:
            outcome = submit_image_update(observe, *args)
            s.in_flight = ImageUpdateInFlight(frame, prior, now_s + self._latency_s, outcome,
                                              name, not cam.health.acquired)
            return None
        outcome = Future()
        try:
            outcome.set_result(observe(*args))
        except Exception as err:  # one failed image never stops the simulation
            outcome.set_exception(err)
        return self._finish(name, frame, prior, outcome, s)

    def _finish(self, name: str, frame: DepthFrame, prior: ImagePrior, outcome: Future,
                s: CpfState, search: bool = False) -> bool:
        """Applies a finished update of camera ``name`` (waiting for it if it is still
        running; ``search``: it was started as one); True when it produced a new
        observation message."""
        try:
            outcome = (self.deadline_waits.join(outcome, search) if self._latency_s > 0
                       else outcome.result())
        except Exception as err:  # one failed image never stops the simulation
            return self._skip(name, frame, f"{type(err).__name__}: {err}")
        cam = s.cameras[name]
        verdict = conclude_image(outcome, cam.health, self._params.health)
        s.cameras[name] = cam = replace(cam, health=verdict.health)
        t = prior.image_time_s
        s.calibration = calibrate_after(s.calibration, name, t, frame, prior.anchor.prior,
                                        verdict.health, self.processors, self._model,
                                        self._params)
        if verdict.observation is None:
            return self._skip(name, frame, verdict.problem, verdict.kind)
        s.message = ImageObservationMessage(s.message.id + 1, frame.sequence, t,
                                            verdict.observation, prior.anchor)
        s.cameras[name] = replace(cam, pacing=cam.pacing.applied(t))
        return True

    def _skip(self, name: str, frame: DepthFrame, problem: str, kind: str = "") -> bool:
        where = f"(camera '{name}') " if self._several else ""
        self.warnings.warn(kind or problem_kind(problem),
                            f"image {frame.sequence} skipped: {where}{problem}")
        return False
