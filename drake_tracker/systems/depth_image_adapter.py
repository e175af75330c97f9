"""Drake depth images in, the tracker's :class:`DepthFrame` out.

A stock ``RgbdSensor`` renders whenever its output is evaluated and carries no capture
time. :class:`ImageStamper` samples it at the camera's rate and holds the image with
its sample time (``RgbdSensorAsync`` provides both itself; ``RgbdSensorDiscrete``'s
``image_time`` port is not usable in drake 1.51). :class:`DepthImageToFrame` watches
the capture time, and for each new one converts the image (``ImageDepth32F`` in
metres or ``ImageDepth16U`` in millimetres) into a ``DepthFrame`` with the next
sequence number. ``AddTracker`` adds it when given an image port.
"""

from __future__ import annotations

import logging

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import (
    DiagramBuilder,
    EventStatus,
    InputPort,
    LeafSystem,
    OutputPort,
)
from pydrake.systems.sensors import ImageDepth16U, ImageDepth32F

from drake_tracker.core.sensors.depth_frames import DepthFrame, depth_to_metres

log = logging.getLogger(__name__)

#: Drake depth image types and their pixel encodings (see ``core.frames``).
IMAGE_ENCODINGS = {ImageDepth32F: "32F_m", ImageDepth16U: "16U_mm"}


def depth_port_kind(port: OutputPort) -> str:
    """``"depth_frame"`` for a DepthFrame port, else the pixel encoding of a Drake depth
    image port (``"32F_m"``, ``"16U_mm"``); anything else is a ValueError."""
    value = port.Allocate().get_value()
    if isinstance(value, DepthFrame):
        return "depth_frame"
    for image_type, encoding in IMAGE_ENCODINGS.items():
        if isinstance(value, image_type):
            return encoding
    raise ValueError(f"depth port '{port.GetFullDescription()}' carries "
                     f"{type(value).__name__}; expected ImageDepth32F, ImageDepth16U or "
                     "DepthFrame")


def _image_type(encoding: str) -> type:
    for image_type, known in IMAGE_ENCODINGS.items():
        if known == encoding:
            return image_type
    raise ValueError(f"unknown depth encoding '{encoding}'; known: "
                     f"{list(IMAGE_ENCODINGS.values())}")


class ImageStamper(LeafSystem):
    """Samples an image every ``period_s`` (from ``offset_s``) and holds it with its
    sample time, the capture stamp a stock ``RgbdSensor`` lacks.

    .. pydrake_system::

        name: ImageStamper
        input_ports:
        - image
        output_ports:
        - image
        - image_time

    ``model_image`` is a value of the image's type (e.g. ``ImageDepth32F()``);
    ``image_time`` (1-vector, s) is NaN before the first sample.
    """

    def __init__(self, *, period_s: float, model_image: object, offset_s: float = 0.0) -> None:
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"ImageStamper: period_s must be > 0, got {period_s}")
        self._image_input = self.DeclareAbstractInputPort(
            "image", AbstractValue.Make(model_image))
        self._image = self.DeclareAbstractState(AbstractValue.Make(model_image))
        self._time = self.DeclareDiscreteState([np.nan])
        self._image_output = self.DeclareStateOutputPort("image", self._image)
        self._time_output = self.DeclareStateOutputPort("image_time", self._time)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._sample)

    def get_image_input_port(self) -> InputPort:
        """The ``image`` input port."""
        return self._image_input

    def get_image_output_port(self) -> OutputPort:
        """The ``image`` output port."""
        return self._image_output

    def get_image_time_output_port(self) -> OutputPort:
        """The ``image_time`` output port."""
        return self._time_output

    def _sample(self, context, state) -> None:
        image = self._image_input.Eval(context)
        state.get_mutable_abstract_state(self._image).set_value(image)
        state.get_mutable_discrete_state(self._time).SetFromVector([context.get_time()])


def AddImageStamper(builder: DiagramBuilder, image: OutputPort, period_s: float,
                    offset_s: float = 0.0, name: str = "image_stamper") -> ImageStamper:
    """Adds an :class:`ImageStamper` that samples the port ``image`` (any Drake image,
    e.g. an RgbdSensor's ``depth_image_32f``) every ``period_s``."""
    stamper = builder.AddNamedSystem(
        name, ImageStamper(period_s=period_s, model_image=image.Allocate().get_value(),
                           offset_s=offset_s))
    builder.Connect(image, stamper.get_image_input_port())
    return stamper


class StoredFrame(DepthFrame):
    """A :class:`DepthFrame` that is never modified once made, so Drake's copies of the
    state holding it (at every check, 1000 a simulated second) share it instead of
    copying a full-resolution image."""

    def __deepcopy__(self, memo) -> StoredFrame:
        return self


class DepthImageToFrame(LeafSystem):
    """Converts each new depth image into a :class:`DepthFrame`: full resolution,
    float32 metres, NaN where the sensor gave no depth.

    .. pydrake_system::

        name: DepthImageToFrame
        input_ports:
        - depth_image
        - image_time
        output_ports:
        - depth_frame

    Every ``period_s`` (from ``offset_s``) it reads ``image_time`` (1-vector, the
    capture time in s); a finite stamp different from the last one marks a new image,
    which is read, converted and given the next sequence number (0, 1, ...). Its
    ``arrival_time_s`` is the update's time. A NaN stamp means "no image yet". An image
    stamped before the previous one is passed on like any other: the tracker applies it
    at its capture time while that is inside its buffer's horizon, and skips it with a
    warning otherwise.
    """

    def __init__(self, *, encoding: str, period_s: float, offset_s: float = 0.0) -> None:
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"DepthImageToFrame: period_s must be > 0, got {period_s}")
        self._encoding = encoding
        self._image_input = self.DeclareAbstractInputPort(
            "depth_image", AbstractValue.Make(_image_type(encoding)()))
        self._time_input = self.DeclareVectorInputPort("image_time", 1)
        self._frame = self.DeclareAbstractState(AbstractValue.Make(DepthFrame.empty()))
        self._frame_output = self.DeclareStateOutputPort("depth_frame", self._frame)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._convert)

    def get_depth_image_input_port(self) -> InputPort:
        """The ``depth_image`` input port."""
        return self._image_input

    def get_image_time_input_port(self) -> InputPort:
        """The ``image_time`` input port."""
        return self._time_input

    def get_depth_frame_output_port(self) -> OutputPort:
        """The ``depth_frame`` output port."""
        return self._frame_output

    def _convert(self, context, state) -> EventStatus | None:
        stamp = float(self._time_input.Eval(context)[0])
        last: DepthFrame = context.get_abstract_state(self._frame).get_value()
        if not np.isfinite(stamp) or stamp == last.capture_time_s:
            return EventStatus.DidNothing()  # Drake keeps the state as it is
        image = self._image_input.Eval(context)
        depth = depth_to_metres(np.asarray(image.data), self._encoding)
        frame = StoredFrame(stamp, context.get_time(), depth, last.sequence + 1)
        state.get_mutable_abstract_state(self._frame).set_value(frame)
        return None
