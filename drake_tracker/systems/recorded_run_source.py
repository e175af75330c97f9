"""Plays a recorded run back into a Diagram: the sensor ports the tracker listens to."""

from __future__ import annotations

import logging

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem, OutputPort

from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.io.recording import RecordedRun

log = logging.getLogger(__name__)


class LatestAtOrBefore:
    """``int(np.searchsorted(times, t, side="right")) - 1`` (the latest index at or before
    ``t``, -1 before the first) for fixed ``times``, from the previous answer when the
    times are sorted and ``t`` moved on by at most one of them: the Simulator asks at
    every step, one sample on (a binary search costs microseconds in numpy)."""

    def __init__(self, times: np.ndarray):
        self._times = np.asarray(times, float)
        self._list = self._times.tolist()
        #: NaN anywhere makes this False: then every answer is numpy's.
        self._sorted = bool(np.all(self._times[1:] >= self._times[:-1]))
        self._at, self._k = float("nan"), -1

    def __call__(self, t: float) -> int:
        """The latest index whose time is at or before ``t`` (-1 for none)."""
        if t == self._at:
            return self._k
        k, times = self._k, self._list
        if self._sorted and (k < 0 or times[k] <= t):
            end = min(k + 4, len(times))  # a few samples on; further, a binary search
            while k + 1 < end and times[k + 1] <= t:
                k += 1
            if k + 1 < len(times) and times[k + 1] <= t:
                k = self._search(t)
        else:
            k = self._search(t)
        self._at, self._k = t, k
        return k

    def _search(self, t: float) -> int:
        return int(np.searchsorted(self._times, t, side="right")) - 1


class _ImageStream:
    """One camera's recorded images, shown at their arrivals (each ``DepthFrame`` made
    once, when it is first shown; image ``i`` has sequence number ``i``)."""

    def __init__(self, name: str, capture_s: np.ndarray, arrival_s: np.ndarray,
                 images: np.ndarray) -> None:
        self.name, self._capture, self._arrival, self._images = name, capture_s, arrival_s, images
        arrivals = np.asarray(arrival_s, float)
        order = np.argsort(arrivals, kind="stable")
        playable = np.isfinite(arrivals[order])
        self.order, self.unplayable = order[playable], order[~playable]
        self._latest = LatestAtOrBefore(arrivals[self.order])
        self._frame_at = (-1, DepthFrame.empty())

    def frame_at(self, t: float) -> DepthFrame:
        """The latest image that arrived at or before ``t`` (``DepthFrame.empty()``
        before the first)."""
        j = self._latest(t)
        if j != self._frame_at[0]:
            if j < 0:
                frame = DepthFrame.empty()
            else:
                i = int(self.order[j])
                frame = DepthFrame(float(self._capture[i]), float(self._arrival[i]),
                                   self._images[i], i)
            self._frame_at = (j, frame)
        return self._frame_at[1]


class RecordedRunSource(LeafSystem):
    """Outputs, at time t, the latest reading stamped at or before t and the latest image
    that arrived at or before t, so a Diagram sees what the live sensors would show.

    .. pydrake_system::

        name: RecordedRunSource
        output_ports:
        - measured_position
        - measurement_time
        - depth_frame

    ``measurement_time`` is -1 before the first reading; ``depth_frame`` is
    ``DepthFrame.empty()`` before the first arrival. Image ``i`` of the run has
    sequence number ``i``. A run of several cameras (``RecordedRun.other_cameras``) has
    a ``<name>_depth_frame`` port for each camera too (the first camera's is also
    ``depth_frame``), each image ``i`` of a camera with sequence number ``i``.
    """

    def __init__(self, run: RecordedRun):
        super().__init__()
        self._run = run
        first = _ImageStream(run.camera_name, run.image_capture_times_s,
                             run.image_arrival_times_s, run.depth_images_m)
        streams = [first] + [_ImageStream(c.name, c.capture_times_s, c.arrival_times_s,
                                          c.depth_images_m) for c in run.other_cameras]
        #: Images whose arrival stamp is not a time: never shown (warned about here).
        self.num_unplayable_images = sum(len(stream.unplayable) for stream in streams)
        for stream in streams:
            if len(stream.unplayable):
                log.warning("%d image(s) of camera '%s' have no finite arrival stamp and "
                            "are never shown (images %s)", len(stream.unplayable),
                            stream.name, stream.unplayable[:10].tolist())
        n = len(run.joint_names)
        self.DeclareVectorOutputPort("measured_position", n, self._calc_position,
                                     {self.time_ticket()})
        self.DeclareVectorOutputPort("measurement_time", 1, self._calc_time,
                                     {self.time_ticket()})
        self._streams = {stream.name: stream for stream in streams}
        self._first = first.name
        self.DeclareAbstractOutputPort("depth_frame", lambda: AbstractValue.Make(
            DepthFrame.empty()), self._calc_frame, {self.time_ticket()})
        for stream in streams if run.other_cameras else ():
            calc = self._calc_frame if stream is first else (
                lambda c, o, name=stream.name: self._calc_camera_frame(c, o, name))
            self.DeclareAbstractOutputPort(
                f"{stream.name}_depth_frame", lambda: AbstractValue.Make(DepthFrame.empty()),
                calc, {self.time_ticket()})
        # The outputs are functions of time alone: the latest lookups are kept (the
        # ports are read at every step, at the same time).
        self._latest_reading = LatestAtOrBefore(run.reading_times_s)

    def get_depth_frame_output_port(self, camera: str | None = None) -> OutputPort:
        """The ``depth_frame`` port of the camera named ``camera`` (None: the first)."""
        if camera is None or (camera == self._first and len(self._streams) == 1):
            return self.GetOutputPort("depth_frame")
        if camera not in self._streams:
            raise ValueError(f"unknown camera '{camera}': the run's cameras are "
                             f"{list(self._streams)}")
        return self.GetOutputPort(f"{camera}_depth_frame")

    def _calc_position(self, context, output: BasicVector):
        k = self._latest_reading(context.get_time())
        output.SetFromVector(self._run.readings_rad[max(k, 0)])

    def _calc_time(self, context, output: BasicVector):
        k = self._latest_reading(context.get_time())
        output.SetAtIndex(0, self._run.reading_times_s[k] if k >= 0 else -1.0)

    def _calc_frame(self, context, output):
        """The first camera's latest image (``depth_frame``)."""
        self._calc_camera_frame(context, output, self._first)

    def _calc_camera_frame(self, context, output, camera: str):
        output.set_value(self._streams[camera].frame_at(context.get_time()))
