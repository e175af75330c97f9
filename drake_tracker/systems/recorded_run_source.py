"""Plays a recorded run back into a Diagram: the sensor ports the tracker listens to."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_tracker.core.frames import DepthFrame
from drake_tracker.recording import RecordedRun


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
        self._arrival_order = np.argsort(run.image_arrival_times_s, kind="stable")
        self._arrivals = run.image_arrival_times_s[self._arrival_order]
        n = len(run.joint_names)
        self.DeclareVectorOutputPort("measured_position", n, self._calc_position,
                                     {self.time_ticket()})
        self.DeclareVectorOutputPort("measurement_time", 1, self._calc_time,
                                     {self.time_ticket()})
        self.DeclareAbstractOutputPort("depth_frame", lambda: AbstractValue.Make(
            DepthFrame.empty()), self._calc_frame, {self.time_ticket()})

    def _latest_reading(self, t: float) -> int:
        return int(np.searchsorted(self._run.reading_times_s, t, side="right")) - 1

    def _calc_position(self, context, output: BasicVector):
        k = self._latest_reading(context.get_time())
        output.SetFromVector(self._run.readings_rad[max(k, 0)])

    def _calc_time(self, context, output: BasicVector):
        k = self._latest_reading(context.get_time())
        output.SetAtIndex(0, self._run.reading_times_s[k] if k >= 0 else -1.0)

    def _calc_frame(self, context, output):
        j = int(np.searchsorted(self._arrivals, context.get_time(), side="right")) - 1
        if j < 0:
            output.set_value(DepthFrame.empty())
            return
        i = int(self._arrival_order[j])
        run = self._run
        output.set_value(DepthFrame(float(run.image_capture_times_s[i]),
                                    float(run.image_arrival_times_s[i]),
                                    run.depth_images_m[i], i))
