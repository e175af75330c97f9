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

The plain ``compressed`` plugin's 16-bit PNG (``"16UC1; png compressed ..."``, a bare PNG
of millimetres) is read too; its topic ends in ``/compressed`` like a colour camera's, so
it is read only when named (``--depth-topic``). JPEG cannot carry depth.

PNG is decoded with Pillow (a dependency of matplotlib). The RVL codec of newer writers
is not read: such a message raises ValueError naming it and how to get past it.
"""

from __future__ import annotations

import io
import struct
from typing import Any

import numpy as np

from drake_tracker.io.ros_messages import DEPTH_ENCODINGS

#: The ``sensor_msgs`` type of a compressed image.
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
#: The last name of the topic ``image_transport`` publishes compressed depth on.
TRANSPORT_SUFFIX = "/compressedDepth"
#: int32 compression format, float32 A and B (little-endian, as the writers' x86 and ARM).
HEADER = struct.Struct("<iff")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The depth encodings in millimetres; the other, ``32FC1``, is in metres.
_MILLIMETRES = tuple(e for e in DEPTH_ENCODINGS if e != "32FC1")


def base_image_topic(topic: str) -> str:
    """The raw image topic a ``compressedDepth`` or ``compressed`` topic was published for
    (``topic`` itself if it is neither): ``/cam/depth/image_raw/compressedDepth`` ->
    ``/cam/depth/image_raw``."""
    for suffix in (TRANSPORT_SUFFIX, "/compressed"):
        if topic.endswith(suffix):
            return topic[:-len(suffix)]
    return topic


def compressed_depth_format(format_field: str) -> tuple[str, str]:
    """(encoding, layout) of a depth ``sensor_msgs/CompressedImage``'s ``format``: layout
    ``compressedDepth`` (the header, then a PNG) or ``png`` (image_transport's plain
    ``compressed`` plugin: a bare 16-bit PNG of millimetres). ValueError naming a format
    that is neither, a codec that is not read, or an encoding that is not depth."""
    encoding, _, transport = (part.strip() for part in str(format_field).partition(";"))
    words = transport.split()
    if words[:1] == ["compressedDepth"] and len(words) <= 2:
        codec = words[1] if len(words) == 2 else "png"
        if encoding not in DEPTH_ENCODINGS:
            raise ValueError(f"compressedDepth encoding '{encoding}' is not a depth encoding "
                             f"(expected one of {', '.join(DEPTH_ENCODINGS)})")
        if codec != "png":
            raise ValueError(f"compressedDepth codec '{codec}' is not read (only png): "
                             f"republish the topic raw (ros2 run image_transport republish "
                             f"compressedDepth raw) or record it with the png codec")
        return encoding, "compressedDepth"
    if words[:2] == ["png", "compressed"] and encoding in _MILLIMETRES:
        return encoding, "png"
    if words[:1] in (["jpeg"], ["jpg"]):
        raise ValueError(f"compressed image format '{format_field}' is JPEG, which is lossy "
                         f"and 8-bit: it cannot carry depth")
    raise ValueError(f"compressed image format '{format_field}' is not depth: expected "
                     f"image_transport's '<encoding>; compressedDepth png', or "
                     f"'16UC1; png compressed ...' from its compressed plugin")


def _png_pixels(png_bytes: bytes) -> np.ndarray:
    """The uint16 (H, W) pixels of a single-channel 16-bit PNG; ValueError otherwise."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(png_bytes)) as png:
            png.load()
            pixels = np.asarray(png)
    except (UnidentifiedImageError, OSError, ValueError) as err:
        raise ValueError(f"depth PNG cannot be decoded: {err}") from err
    if pixels.ndim != 2 or pixels.size == 0 or not (
            np.issubdtype(pixels.dtype, np.integer) and pixels.min() >= 0
            and pixels.max() <= 0xFFFF):
        raise ValueError(f"depth PNG is {pixels.dtype} {pixels.shape}, not a "
                         f"single-channel 16-bit image")
    return pixels.astype(np.uint16)


def depth_from_compressed(message: Any) -> np.ndarray:
    """The (H, W) depth of a depth ``sensor_msgs/CompressedImage`` (see
    :func:`compressed_depth_format`), as ``ros_messages.depth_from_image`` gives a raw
    one: uint16 millimetres for ``16UC1``/``mono16``, float32 metres (NaN: no return) for
    ``32FC1``. Raises ValueError naming the problem (format, header, PNG, quantisation)."""
    encoding, layout = compressed_depth_format(message.format)
    data = bytes(np.asarray(message.data, np.uint8))
    if layout == "png":
        return _png_pixels(data)
    if len(data) <= HEADER.size or not data[HEADER.size:].startswith(PNG_SIGNATURE):
        raise ValueError(f"compressedDepth message of {len(data)} bytes does not hold a "
                         f"{HEADER.size}-byte header followed by a PNG image")
    _, quant_a, quant_b = HEADER.unpack_from(data)
    values = _png_pixels(data[HEADER.size:])
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
