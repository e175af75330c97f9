"""Depth that ROS's ``image_transport`` recorded through its ``compressedDepth`` plugin: a
``sensor_msgs/CompressedImage`` on ``<image topic>/compressedDepth``, the form a robot's
depth camera is often logged in to keep bags small.

The message's ``format`` is ``"<encoding>; compressedDepth [png|rvl]"`` (older writers:
``"<encoding>; compressedDepth"``, which is PNG). Its ``data`` is a 12-byte header, a
little-endian int32 (the compression format) and two float32 quantisation parameters A
and B, followed by the compressed image:

* ``16UC1``/``mono16``: a 16-bit PNG of the millimetres themselves (0: no return; the
  writer zeroes depths beyond its ``depth_max`` too);
* ``32FC1``: a 16-bit PNG of quantised inverse depth v, from which depth (metres) is
  ``A / (v - B)``, and v = 0 is no return (NaN).

PNG is decoded with Pillow (a dependency of matplotlib). The RVL codec of newer writers
is not read: such a message raises ValueError naming it and how to get past it.
"""

from __future__ import annotations

import io
import struct
from typing import Any

import numpy as np

#: The ``sensor_msgs`` type of a compressed image.
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
#: The last name of the topic ``image_transport`` publishes compressed depth on.
TRANSPORT_SUFFIX = "/compressedDepth"
#: int32 compression format, float32 A and B (little-endian, as the writers' x86 and ARM).
HEADER = struct.Struct("<iff")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_MILLIMETRES = ("16UC1", "mono16")
_METRES = "32FC1"


def base_image_topic(topic: str) -> str:
    """The raw image topic a ``compressedDepth`` topic was published for (``topic``
    itself if it is not one): ``/cam/depth/image_raw/compressedDepth`` ->
    ``/cam/depth/image_raw``."""
    return topic[:-len(TRANSPORT_SUFFIX)] if topic.endswith(TRANSPORT_SUFFIX) else topic


def compressed_depth_format(format_field: str) -> tuple[str, str]:
    """(encoding, codec) of a ``compressedDepth`` message's ``format``; ValueError naming
    a format that is not one, or an encoding that is not a depth encoding."""
    encoding, _, transport = (part.strip() for part in str(format_field).partition(";"))
    words = transport.split()
    if not words or words[0] != "compressedDepth" or len(words) > 2:
        raise ValueError(f"compressed image format '{format_field}' is not image_transport's "
                         f"compressedDepth (expected '<encoding>; compressedDepth png')")
    codec = words[1] if len(words) == 2 else "png"
    if encoding not in _MILLIMETRES + (_METRES,):
        raise ValueError(f"compressedDepth encoding '{encoding}' is not a depth encoding "
                         f"(expected one of {', '.join(_MILLIMETRES + (_METRES,))})")
    if codec != "png":
        raise ValueError(f"compressedDepth codec '{codec}' is not read (only png): "
                         f"republish the topic raw (ros2 run image_transport republish "
                         f"{codec} raw) or record it with the png codec")
    return encoding, codec


def depth_from_compressed(message: Any) -> np.ndarray:
    """The (H, W) depth of a ``compressedDepth`` ``sensor_msgs/CompressedImage``, as
    ``ros_messages.depth_from_image`` gives a raw one: uint16 millimetres for
    ``16UC1``/``mono16``, float32 metres (NaN: no return) for ``32FC1``. Raises ValueError
    naming the problem (format, header, PNG data, quantisation)."""
    from PIL import Image, UnidentifiedImageError

    encoding, _ = compressed_depth_format(message.format)
    data = bytes(np.asarray(message.data, np.uint8))
    if len(data) <= HEADER.size or not data[HEADER.size:].startswith(PNG_SIGNATURE):
        raise ValueError(f"compressedDepth message of {len(data)} bytes does not hold a "
                         f"{HEADER.size}-byte header followed by a PNG image")
    _, quant_a, quant_b = HEADER.unpack_from(data)
    try:
        with Image.open(io.BytesIO(data[HEADER.size:])) as png:
            png.load()
            pixels = np.asarray(png)
    except (UnidentifiedImageError, OSError, ValueError) as err:
        raise ValueError(f"compressedDepth PNG cannot be decoded: {err}") from err
    if pixels.ndim != 2 or pixels.size == 0 or not (
            np.issubdtype(pixels.dtype, np.integer) and pixels.min() >= 0
            and pixels.max() <= 0xFFFF):
        raise ValueError(f"compressedDepth PNG is {pixels.dtype} {pixels.shape}, not a "
                         f"single-channel 16-bit image")
    values = pixels.astype(np.uint16)
    if encoding in _MILLIMETRES:
        return values
    if not (np.isfinite(quant_a) and np.isfinite(quant_b) and quant_a > 0):
        raise ValueError(f"compressedDepth 32FC1 quantisation A = {quant_a}, B = {quant_b} "
                         f"cannot give depths (A must be finite and > 0, B finite)")
    v = values.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(values > 0, quant_a / (v - quant_b), np.nan)
    # Writers keep v above B for every depth they code; anything else is no return.
    depth[~np.isfinite(depth) | (depth <= 0)] = np.nan
    return depth.astype(np.float32)
