"""Drake LCM messages in and out of the tracker's Diagram (``examples/lcm_live.py``).

The status needs nothing of ours: Drake's ``IiwaStatusReceiver`` gives the measured
positions and ``time_measured`` (the message's ``utime`` in s). The depth comes as an
``lcmt_image_array`` from an ``LcmSubscriberSystem``: :class:`LcmImageArrayToDepth`
turns it into the depth image and capture time ``AddTracker`` takes. The estimate goes
out as an ``lcmt_viewer_draw`` (:class:`PoseToLcmViewerDraw`): Drake's message for
named frames' poses, which its viewers and ``lcm-spy`` show as they are.
"""

from __future__ import annotations

import logging

import numpy as np
from drake import lcmt_image_array, lcmt_viewer_draw
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, InputPort, LeafSystem, OutputPort
from pydrake.systems.sensors import ImageDepth32F

from drake_tracker.core.sensors.depth_frames import depth_to_metres
from drake_tracker.core.sensors.rate_limited_warning import RateLimitedWarning
from drake_tracker.io.lcm_messages import depth_from_image_array

log = logging.getLogger(__name__)


class LcmImageArrayToDepth(LeafSystem):
    """The first depth image of an ``lcmt_image_array`` (``io/lcm_messages.py``: uint16
    mm or float32 m, raw or zlib) as an ``ImageDepth32F`` in metres, and its capture time.

    .. pydrake_system::

        name: LcmImageArrayToDepth
        input_ports:
        - lcmt_image_array
        output_ports:
        - depth_image
        - image_time

    ``image_time`` (1-vector, s) is the depth image's ``header.utime`` over 1e6; NaN
    before the first message and for a message without a usable depth image of
    ``width`` x ``height``, which is skipped (``DepthImageToFrame`` waits for the next)
    with a rate-limited warning and counted in ``skipped`` (by reason).
    """

    def __init__(self, *, width: int, height: int) -> None:
        super().__init__()
        self._size = (int(height), int(width))
        self._input = self.DeclareAbstractInputPort(
            "lcmt_image_array", AbstractValue.Make(lcmt_image_array()))
        only_input = {self.input_port_ticket(self._input.get_index())}
        self._depth = self.DeclareAbstractOutputPort(
            "depth_image", lambda: AbstractValue.Make(ImageDepth32F(int(width), int(height))),
            self._calc_depth, only_input)
        self._time = self.DeclareVectorOutputPort("image_time", 1, self._calc_time,
                                                  only_input)
        self.warnings = RateLimitedWarning(log)
        self._judged: tuple[int, str] | None = None

    @property
    def skipped(self) -> dict[str, int]:
        """Messages skipped so far, by reason."""
        return dict(self.warnings.counts)

    def get_image_array_input_port(self) -> InputPort:
        """The ``lcmt_image_array`` input port."""
        return self._input

    def get_depth_image_output_port(self) -> OutputPort:
        """The ``depth_image`` output port."""
        return self._depth

    def get_image_time_output_port(self) -> OutputPort:
        """The ``image_time`` output port."""
        return self._time

    def _decoded(self, context) -> tuple[float, np.ndarray | None]:
        array = self._input.Eval(context)
        if array.num_images == 0 and array.header.utime == 0:
            return np.nan, None  # the subscriber's default message: nothing received yet
        try:
            utime, depth = depth_from_image_array(array)
            if depth.shape != self._size:
                raise ValueError(f"a {depth.shape[1]}x{depth.shape[0]} depth image, the "
                                 f"camera is {self._size[1]}x{self._size[0]}")
        except ValueError as err:
            key = (int(array.header.utime), str(err))
            if key != self._judged:  # once per message, however often it is evaluated
                self._judged = key
                self.warnings.warn("depth images not usable", f"image array stamped "
                                   f"{array.header.utime} µs skipped: {err}")
            return np.nan, None
        return utime / 1e6, depth

    def _calc_depth(self, context, output) -> None:
        _, depth = self._decoded(context)
        if depth is not None:
            encoding = "16U_mm" if depth.dtype == np.uint16 else "32F_m"
            output.get_mutable_value().mutable_data[:, :, 0] = depth_to_metres(depth, encoding)

    def _calc_time(self, context, output: BasicVector) -> None:
        output.SetAtIndex(0, self._decoded(context)[0])


class PoseToLcmViewerDraw(LeafSystem):
    """A pose (``RigidTransform``) as an ``lcmt_viewer_draw`` of one link called
    ``name``: position (m) and quaternion (w, x, y, z), float32 as the message holds
    them; ``timestamp`` in ms of simulated time, as Drake's viewers stamp it.

    .. pydrake_system::

        name: PoseToLcmViewerDraw
        input_ports:
        - pose
        output_ports:
        - lcmt_viewer_draw
    """

    def __init__(self, *, name: str) -> None:
        super().__init__()
        self._name = name
        self._pose = self.DeclareAbstractInputPort("pose", AbstractValue.Make(RigidTransform()))
        self._message = self.DeclareAbstractOutputPort(
            "lcmt_viewer_draw", lambda: AbstractValue.Make(lcmt_viewer_draw()), self._calc)

    def get_pose_input_port(self) -> InputPort:
        """The ``pose`` input port."""
        return self._pose

    def get_message_output_port(self) -> OutputPort:
        """The ``lcmt_viewer_draw`` output port."""
        return self._message

    def _calc(self, context, output) -> None:
        X = self._pose.Eval(context)
        q = X.rotation().ToQuaternion()
        message = lcmt_viewer_draw()
        message.timestamp = int(round(context.get_time() * 1000))
        message.num_links = 1
        message.link_name = [self._name]
        message.robot_num = [0]
        message.position = [[float(v) for v in X.translation()]]
        message.quaternion = [[q.w(), q.x(), q.y(), q.z()]]
        output.set_value(message)
