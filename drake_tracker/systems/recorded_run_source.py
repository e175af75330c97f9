"""Plays a recorded run back into a Diagram: the sensor ports the tracker listens to."""

from __future__ import annotations

import logging

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

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
    sequence number ``i``.
    """

    def __init__(self, run: RecordedRun):
        super().__init__()
        self._run = run
        self._arrival_order, unplayable = run.images_in_arrival_order()
        #: Images whose arrival stamp is not a time: never shown (warned about here).
        self.num_unplayable_images = len(unplayable)
        if self.num_unplayable_images:
            log.warning("%d image(s) of the run have no finite arrival stamp and are never "
                        "shown (images %s)", self.num_unplayable_images,
                        unplayable[:10].tolist())
        self._arrivals = run.image_arrival_times_s[self._arrival_order]
        n = len(run.joint_names)
        self.DeclareVectorOutputPort("measured_position", n, self._calc_position,
                                     {self.time_ticket()})
        self.DeclareVectorOutputPort("measurement_time", 1, self._calc_time,
                                     {self.time_ticket()})
        self.DeclareAbstractOutputPort("depth_frame", lambda: AbstractValue.Make(
            DepthFrame.empty()), self._calc_frame, {self.time_ticket()})
        # The outputs are functions of time alone: the latest lookups are kept (the
        # three ports are read at every step, at the same time), and each image's
        # DepthFrame is made once, when it is first shown.
        self._latest_reading = LatestAtOrBefore(run.reading_times_s)
        self._latest_arrival = LatestAtOrBefore(self._arrivals)
        self._frame_at = (-1, DepthFrame.empty())

    def _calc_position(self, context, output: BasicVector):
        k = self._latest_reading(context.get_time())
        output.SetFromVector(self._run.readings_rad[max(k, 0)])

    def _calc_time(self, context, output: BasicVector):
        k = self._latest_reading(context.get_time())
        output.SetAtIndex(0, self._run.reading_times_s[k] if k >= 0 else -1.0)

    def _calc_frame(self, context, output):
        j = self._latest_arrival(context.get_time())
        if j != self._frame_at[0]:
            self._frame_at = (j, self._frame(j))
        output.set_value(self._frame_at[1])

    def _frame(self, j: int) -> DepthFrame:
        """The j-th image to arrive (``DepthFrame.empty()`` for j < 0)."""
        if j < 0:
            return DepthFrame.empty()
        i = int(self._arrival_order[j])
        run = self._run
        return DepthFrame(float(run.image_capture_times_s[i]),
                          float(run.image_arrival_times_s[i]), run.depth_images_m[i], i)
