"""Depth logged through image_transport's ``compressedDepth`` plugin
(``io/compressed_depth.py``), and bags that carry it (``io/bag_source.py``).

The messages are built here as the plugin builds them (its documented layout: a 12-byte
header of int32 format and float32 A, B, then a PNG from Pillow; for 32FC1 the
quantised inverse depth v = A / d + B, truncated to uint16), and as the plain
``compressed`` plugin writes a 16-bit image (a bare PNG). A bag rewritten with its depth
in that form is tracked to the same estimates as its raw 16UC1 twin.
"""

from __future__ import annotations

import io
import struct

import numpy as np
import pytest

pytest.importorskip("rosbags")
from fast_params import small_params as fast_params  # noqa: E402
from PIL import Image  # noqa: E402

from drake_tracker.io.bag_source import BagSource, BagTopics  # noqa: E402
from drake_tracker.io.compressed_depth import (  # noqa: E402
    base_image_topic,
    depth_from_compressed,
)
from drake_tracker.io.estimates_out import read_estimates_csv  # noqa: E402
from drake_tracker.io.ros_messages import RosMessages, bag_writer  # noqa: E402
from drake_tracker.io.run_bag import write_run_bag  # noqa: E402
from drake_tracker.io.stream import ImageEvent  # noqa: E402
from drake_tracker.io.synthetic import synthetic_run  # noqa: E402
from drake_tracker.io.track_files import track_bag  # noqa: E402

M = RosMessages()
COMPRESSED = "sensor_msgs/msg/CompressedImage"


def png16(values: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(values, np.uint16)).save(buffer, format="PNG")
    return buffer.getvalue()


def compressed(stamp_ns: int, fmt: str, payload: bytes, a: float = 0.0, b: float = 0.0):
    data = struct.pack("<iff", 0, a, b) + payload
    return M.types[COMPRESSED](header=M.header(stamp_ns, "cam"), format=fmt,
                               data=np.frombuffer(data, np.uint8).copy())


def millimetres_message(stamp_ns: int, mm: np.ndarray, fmt="16UC1; compressedDepth png"):
    return compressed(stamp_ns, fmt, png16(mm))


def inverse_depth_message(stamp_ns: int, metres: np.ndarray, quantization: float = 100.0,
                          depth_max: float = 10.0):
    """The plugin's 32FC1 coding: A = q (q + 1), B = 1 - A / depth_max; v = A / d + B
    truncated, 0 where there is no depth or it is at or beyond depth_max."""
    a = np.float32(quantization * (quantization + 1.0))
    b = np.float32(1.0 - a / np.float32(depth_max))
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.where(np.isfinite(metres) & (metres < depth_max), a / metres + b, 0.0)
    return compressed(stamp_ns, "32FC1; compressedDepth png", png16(np.trunc(v)), a, b)


def test_millimetres_decode_exactly_in_every_format_spelling():
    mm = np.array([[0, 1, 999], [2500, 40000, 65535]], np.uint16)
    for fmt in ("16UC1; compressedDepth png", "16UC1; compressedDepth", "mono16; compressedDepth"):
        depth = depth_from_compressed(millimetres_message(0, mm, fmt))
        assert depth.dtype == np.uint16
        np.testing.assert_array_equal(depth, mm)


def test_the_plain_compressed_plugins_png_is_millimetres():
    """image_transport's ``compressed`` plugin writes a 16-bit image as a bare PNG (no
    header)."""
    mm = np.array([[0, 7, 1234], [4000, 0, 65535]], np.uint16)
    message = M.types[COMPRESSED](header=M.header(0, "cam"),
                                  format="16UC1; png compressed mono16",
                                  data=np.frombuffer(png16(mm), np.uint8).copy())
    np.testing.assert_array_equal(depth_from_compressed(message), mm)


def test_inverse_depth_decodes_within_its_quantisation():
    """One quantisation step of v is a depth step of d^2 / A at depth d (0.4 mm at 2 m
    with the plugin's defaults): the decoded depth lies within one step of the truth;
    no depth, and depth beyond depth_max, decode as NaN."""
    rng = np.random.default_rng(3)
    metres = rng.uniform(0.3, 9.9, (12, 16)).astype(np.float32)
    metres[0, :4] = np.nan
    metres[1, :3] = 12.0
    depth = depth_from_compressed(inverse_depth_message(0, metres))
    assert depth.dtype == np.float32
    hidden = ~np.isfinite(metres) | (metres >= 10.0)
    assert np.isnan(depth[hidden]).all() and np.isfinite(depth[~hidden]).all()
    step = metres[~hidden].astype(float) ** 2 / (100.0 * 101.0)
    assert np.all(np.abs(depth[~hidden] - metres[~hidden]) <= 1.01 * step + 1e-6)


def test_bad_messages_are_named():
    mm = np.ones((2, 3), np.uint16)
    cases = [
        (millimetres_message(0, mm, "16UC1; compressedDepth rvl"), "codec 'rvl' is not read"),
        (millimetres_message(0, mm, "png"), "is not depth"),
        (millimetres_message(0, mm, "rgb8; jpeg compressed bgr8"), "JPEG, which is lossy"),
        (millimetres_message(0, mm, "32FC1; png compressed"), "is not depth"),
        (millimetres_message(0, mm, "rgb8; compressedDepth png"), "'rgb8' is not a depth"),
        (compressed(0, "16UC1; compressedDepth png", b""), "does not hold"),
        (compressed(0, "16UC1; compressedDepth png", png16(mm)[:20]), "cannot be decoded"),
        (compressed(0, "32FC1; compressedDepth png", png16(mm), 0.0, 1.0), "quantisation"),
    ]
    for message, match in cases:
        with pytest.raises(ValueError, match=match):
            depth_from_compressed(message)
    eight_bit = io.BytesIO()
    Image.fromarray(np.zeros((2, 3, 3), np.uint8)).save(eight_bit, format="PNG")
    with pytest.raises(ValueError, match="not a single-channel 16-bit"):
        depth_from_compressed(compressed(0, "16UC1; compressedDepth png", eight_bit.getvalue()))


def test_base_image_topic():
    assert base_image_topic("/cam/depth/image_raw/compressedDepth") == "/cam/depth/image_raw"
    assert base_image_topic("/cam/depth/image_raw/compressed") == "/cam/depth/image_raw"
    assert base_image_topic("/cam/depth/image_raw") == "/cam/depth/image_raw"


def _rewrite(source, target, depth_as):
    """Copies a bag, each depth Image replaced by ``depth_as(stamp_ns, metres)`` ->
    (topic, type, message); a JPEG colour topic is added beside it, which is not depth."""
    from rosbags.highlevel import AnyReader

    writer = bag_writer(target)
    connections = {}

    def put(topic, kind, stamp, message):
        if topic not in connections:
            connections[topic] = writer.add_connection(topic, kind, typestore=M.store)
        writer.write(connections[topic], stamp, M.serialize(message))

    with AnyReader([source]) as reader:
        for connection, log_ns, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            if connection.msgtype != "sensor_msgs/msg/Image":
                put(connection.topic, connection.msgtype, log_ns, message)
                continue
            metres = np.frombuffer(bytes(message.data), "<f4").reshape(
                message.height, message.width)
            stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
            topic, kind, out = depth_as(stamp, metres)
            put(topic, kind, log_ns, out)
            colour = M.types[COMPRESSED](header=M.header(stamp, "cam"),
                                         format="rgb8; jpeg compressed bgr8",
                                         data=np.zeros(4, np.uint8))
            put("/camera/color/image_raw/compressed", COMPRESSED, log_ns, colour)
    writer.close()
    return target


def _mm(metres):
    return np.where(np.isfinite(metres), np.round(metres * 1000.0), 0).astype(np.uint16)


def test_a_compressed_depth_bag_tracks_as_its_raw_twin(apollo, tmp_path):
    run = synthetic_run(apollo, duration_s=0.5, encoder_rate_hz=200.0,
                        seed=5).stamped_in_nanoseconds()
    plain = tmp_path / "plain.mcap"
    write_run_bag(run, plain)
    topic = "/camera/depth/image_raw"
    raw = _rewrite(plain, tmp_path / "raw.mcap", lambda stamp, metres: (
        topic, "sensor_msgs/msg/Image", M.depth_image(stamp, "cam", _mm(metres))))
    packed = _rewrite(plain, tmp_path / "packed.mcap", lambda stamp, metres: (
        topic + "/compressedDepth", COMPRESSED, millimetres_message(stamp, _mm(metres))))
    names = apollo.robot_joint_names
    source = BagSource(packed, names)
    # Found by its transport's name, its CameraInfo beside the raw topic it stands for.
    assert source.depth_topic == topic + "/compressedDepth"
    assert source.camera_info_topic == "/camera/depth/camera_info"
    images = [e.depth for e in source.events() if isinstance(e, ImageEvent)]
    expected = [_mm(d) for d in run.depth_images_m]
    assert len(images) == len(expected) > 5
    for got, want in zip(images, expected):
        np.testing.assert_array_equal(got, want)
    # The plain compressed plugin's PNG shares its topic's last name with the colour
    # camera's: read only when named.
    plain_png = _rewrite(plain, tmp_path / "png.mcap", lambda stamp, metres: (
        topic + "/compressed", COMPRESSED, M.types[COMPRESSED](
            header=M.header(stamp, "cam"), format="16UC1; png compressed mono16",
            data=np.frombuffer(png16(_mm(metres)), np.uint8).copy())))
    with pytest.raises(ValueError, match="the bag has 0 depth"):
        BagSource(plain_png, names)
    named = BagSource(plain_png, names, BagTopics(depth=topic + "/compressed"))
    assert named.camera_info_topic == "/camera/depth/camera_info"
    for got, want in zip([e.depth for e in named.events() if isinstance(e, ImageEvent)],
                         expected, strict=True):
        np.testing.assert_array_equal(got, want)
    params = fast_params()
    a = track_bag(BagSource(raw, names), apollo, params, tmp_path / "a", progress=False)
    b = track_bag(BagSource(packed, names), apollo, params, tmp_path / "b", progress=False)
    assert a["counts"] == b["counts"] and a["counts"]["images_applied"] > 3
    ea, eb = (read_estimates_csv(tmp_path / f / "estimates.csv") for f in "ab")
    for column in ea:
        if column not in ("health", "t0_s"):
            np.testing.assert_array_equal(eb[column], ea[column], err_msg=column)
    assert (ea["health"] == eb["health"]).all()
