"""Drake's LCM messages as the tracker reads and writes them, and the ``lcm`` extra.

The message classes are Drake's own (``from drake import lcmt_iiwa_status, ...``: they
ship with the drake wheel and need nothing else to encode and decode). Only log files
(``lcm.EventLog``) need the ``lcm`` package: :func:`require_lcm` says so in one line.

* Status: ``lcmt_iiwa_status.joint_position_measured`` or
  ``lcmt_panda_status.joint_position``, told apart by the message's fingerprint (its
  first 8 bytes); joints in the model's order (the messages carry no names).
* Depth: the first ``lcmt_image`` of an ``lcmt_image_array`` whose pixel format is
  ``PIXEL_FORMAT_DEPTH``: ``CHANNEL_TYPE_UINT16`` (millimetres, 0: no return) or
  ``CHANNEL_TYPE_FLOAT32`` (metres), ``COMPRESSION_METHOD_NOT_COMPRESSED`` or ``_ZLIB``,
  either byte order, rows of ``row_stride`` bytes.
* The camera: an ``lcmt_image`` carries no intrinsics, so they are given as text,
  ``WIDTHxHEIGHT:fx,fy,cx,cy`` (pixels), e.g. ``80x60:69.28,69.28,39.5,29.5``.
"""

from __future__ import annotations

import struct
import zlib
from typing import Any

import numpy as np
from drake import lcmt_header, lcmt_iiwa_status, lcmt_image, lcmt_image_array, lcmt_panda_status

from drake_tracker.core.sensors.camera import CameraIntrinsics

#: Drake's default channel names (its LcmIiwaStatus / Panda drivers and camera publisher).
IIWA_STATUS = "IIWA_STATUS"
PANDA_STATUS = "PANDA_STATUS"
DRAKE_RGBD_CAMERA_IMAGES = "DRAKE_RGBD_CAMERA_IMAGES"
#: The status types the tracker reads, by name, and the field holding the positions.
STATUS_TYPES = {"iiwa": (lcmt_iiwa_status, "joint_position_measured"),
                "panda": (lcmt_panda_status, "joint_position")}
#: Depth channel types: the numpy dtype of their pixels.
DEPTH_CHANNEL_TYPES = {lcmt_image.CHANNEL_TYPE_UINT16: np.dtype("u2"),
                       lcmt_image.CHANNEL_TYPE_FLOAT32: np.dtype("f4")}
COMPRESSIONS = {lcmt_image.COMPRESSION_METHOD_NOT_COMPRESSED: "none",
                lcmt_image.COMPRESSION_METHOD_ZLIB: "zlib"}


def require_lcm() -> None:
    """Raises ImportError (one line, naming the extra) unless ``lcm`` is installed."""
    try:
        import lcm  # noqa: F401
    except ImportError as err:
        raise ImportError("reading or writing LCM logs needs the 'lcm' extra: pip install "
                          "'drake_tracker[lcm]' (the lcm library)") from err


def status_type_of(data: bytes) -> str | None:
    """``"iiwa"`` or ``"panda"`` from an encoded status message's fingerprint; None for
    any other message."""
    for name, (kind, _) in STATUS_TYPES.items():
        if bytes(data[:8]) == kind._get_packed_fingerprint():
            return name
    return None


def decode(kind: type, data: bytes) -> Any:
    """The ``kind`` message encoded in ``data``; raises ValueError when the bytes are not
    one (another type, cut short)."""
    try:
        return kind.decode(data)
    except (ValueError, struct.error) as err:
        raise ValueError(f"not an {kind.__name__} ({len(data)} bytes): {err}") from None


def decode_status(data: bytes, status_type: str) -> tuple[int, np.ndarray]:
    """(utime, joint positions) of an encoded status message of ``status_type``. Raises
    ValueError when the bytes are not one."""
    kind, field = STATUS_TYPES[status_type]
    message = decode(kind, data)
    return int(message.utime), np.asarray(getattr(message, field), float)


def status_message(utime: int, positions: np.ndarray) -> bytes:
    """An encoded ``lcmt_iiwa_status`` holding ``positions`` as the measured positions
    (the other arrays zero, of the same length: any joint count)."""
    message = lcmt_iiwa_status()
    message.utime = int(utime)
    message.num_joints = len(positions)
    message.joint_position_measured = [float(q) for q in positions]
    zeros = [0.0] * len(positions)
    for field in ("joint_velocity_estimated", "joint_position_commanded", "joint_position_ipo",
                  "joint_torque_measured", "joint_torque_commanded", "joint_torque_external"):
        setattr(message, field, zeros)
    return message.encode()


def depth_image_message(utime: int, depth: np.ndarray, compress: bool = False,
                        frame_name: str = "depth") -> lcmt_image:
    """An ``lcmt_image`` of an (H, W) depth image: float32 metres or uint16 millimetres
    (by ``depth``'s dtype), little-endian, zlib-compressed when ``compress``."""
    depth = np.ascontiguousarray(depth)
    channel = {np.dtype("f4"): lcmt_image.CHANNEL_TYPE_FLOAT32,
               np.dtype("u2"): lcmt_image.CHANNEL_TYPE_UINT16}[depth.dtype]
    image = lcmt_image()
    image.header = lcmt_header()
    image.header.utime = int(utime)
    image.header.frame_name = frame_name
    image.height, image.width = depth.shape
    image.row_stride = depth.shape[1] * depth.dtype.itemsize
    raw = depth.astype(depth.dtype.newbyteorder("<")).tobytes()
    image.data = zlib.compress(raw) if compress else raw
    image.size = len(image.data)
    image.bigendian = False
    image.pixel_format = lcmt_image.PIXEL_FORMAT_DEPTH
    image.channel_type = channel
    image.compression_method = (lcmt_image.COMPRESSION_METHOD_ZLIB if compress
                                else lcmt_image.COMPRESSION_METHOD_NOT_COMPRESSED)
    return image


def image_array_message(utime: int, images: list[lcmt_image]) -> bytes:
    """An encoded ``lcmt_image_array`` of ``images`` stamped ``utime``."""
    array = lcmt_image_array()
    array.header = lcmt_header()
    array.header.utime = int(utime)
    array.num_images = len(images)
    array.images = list(images)
    return array.encode()


def depth_from_image_array(array: lcmt_image_array) -> tuple[int, np.ndarray]:
    """(capture utime, (H, W) depth) of the first depth image of ``array``: uint16
    millimetres or float32 metres. Raises ValueError naming what is wrong: no depth
    image, an unknown channel type or compression, data that does not hold the image."""
    formats = []
    for image in array.images:
        if image.pixel_format == lcmt_image.PIXEL_FORMAT_DEPTH:
            return int(image.header.utime), depth_from_image(image)
        formats.append(int(image.pixel_format))
    raise ValueError(f"the image array holds no depth image (PIXEL_FORMAT_DEPTH = "
                     f"{lcmt_image.PIXEL_FORMAT_DEPTH}); its pixel formats: {formats}")


def depth_from_image(image: lcmt_image) -> np.ndarray:
    """The (H, W) pixels of a depth ``lcmt_image`` (see :func:`depth_from_image_array`)."""
    dtype = DEPTH_CHANNEL_TYPES.get(int(image.channel_type))
    if dtype is None:
        raise ValueError(f"depth image channel type {image.channel_type} is not "
                         f"CHANNEL_TYPE_UINT16 (mm) or CHANNEL_TYPE_FLOAT32 (m)")
    compression = COMPRESSIONS.get(int(image.compression_method))
    if compression is None:
        raise ValueError(f"depth image compression method {image.compression_method} is "
                         f"not NOT_COMPRESSED or ZLIB")
    data = bytes(image.data)
    if compression == "zlib":
        try:
            data = zlib.decompress(data)
        except zlib.error as err:
            raise ValueError(f"depth image: zlib data cannot be decompressed: {err}") from None
    h, w, stride = int(image.height), int(image.width), int(image.row_stride)
    if h <= 0 or w <= 0 or stride < w * dtype.itemsize or len(data) < h * stride:
        raise ValueError(f"depth image of {w}x{h} (row stride {stride}) has {len(data)} "
                         f"bytes of data: truncated or inconsistent")
    dtype = dtype.newbyteorder(">" if image.bigendian else "<")
    rows = np.frombuffer(data, np.uint8, h * stride).reshape(h, stride)[:, :w * dtype.itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(dtype.newbyteorder("="))


def camera_channel(name: str) -> str:
    """The ``lcmt_image_array`` channel of camera ``name`` where there are several:
    ``DRAKE_RGBD_CAMERA_IMAGES_<name>``, the channel Drake's ``ApplyCameraConfig``
    publishes a named camera's images on."""
    return f"{DRAKE_RGBD_CAMERA_IMAGES}_{name}"


def camera_from_text(text: str) -> CameraIntrinsics:
    """The intrinsics written ``WIDTHxHEIGHT:fx,fy,cx,cy``. Raises ValueError showing the
    expected form."""
    try:
        size, values = text.split(":")
        width, height = (int(v) for v in size.lower().split("x"))
        fx, fy, cx, cy = (float(v) for v in values.split(","))
        return CameraIntrinsics(width, height, fx, fy, cx, cy)
    except ValueError as err:
        raise ValueError(f"camera '{text}' is not WIDTHxHEIGHT:fx,fy,cx,cy "
                         f"(e.g. 80x60:69.28,69.28,39.5,29.5): {err}") from None


def camera_text(camera: CameraIntrinsics) -> str:
    """``camera`` as :func:`camera_from_text` reads it (exact: ``repr`` of the floats)."""
    return (f"{camera.width}x{camera.height}:{float(camera.fx)!r},{float(camera.fy)!r},"
            f"{float(camera.cx)!r},{float(camera.cy)!r}")
