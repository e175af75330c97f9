"""LCM logs in and out (``io/lcm_log.py``, ``io/run_lcm_log.py``, ``track --lcm-log``).

The round trip: a run stamped in whole µs, written as an lcm-logger file and tracked
from it with ``drake-tracker track --lcm-log``, gives the same estimates as the run
tracked with ``track --run`` (the estimates file, to 1e-9; here exactly). Depth written
as zlib-compressed float32 or uint16 mm reads back as written. Bad input: each fault
named, or skipped and counted.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

pytest.importorskip("lcm")

import lcm  # noqa: E402
from cli_runs import assert_one_line_error, run_cli  # noqa: E402
from drake import lcmt_image, lcmt_panda_status  # noqa: E402
from fast_params import small_params  # noqa: E402

from drake_tracker.io.estimates_out import read_estimates_csv, stamp_text  # noqa: E402
from drake_tracker.io.lcm_log import LcmLogSource  # noqa: E402
from drake_tracker.io.lcm_messages import (  # noqa: E402
    camera_from_text,
    camera_text,
    depth_image_message,
    image_array_message,
    require_lcm,
    status_message,
)
from drake_tracker.io.run_lcm_log import DEFAULT_BASE_US, millimetres, write_run_lcm_log  # noqa: E402
from drake_tracker.io.synthetic import synthetic_run  # noqa: E402
from drake_tracker.io.track_files import track_lcm_log  # noqa: E402
from drake_tracker.params.loading import tracker_params_to_yaml  # noqa: E402


@pytest.fixture(scope="module")
def run(apollo):
    return synthetic_run(apollo, duration_s=0.6, encoder_rate_hz=200.0,
                         seed=7).stamped_in_microseconds()


@pytest.fixture(scope="module")
def log(run, tmp_path_factory):
    path = tmp_path_factory.mktemp("lcm") / "run.lcmlog"
    write_run_lcm_log(run, path)
    return path


def test_stamps_in_microseconds_are_what_a_log_holds(run):
    for times in (run.reading_times_s, run.image_capture_times_s, run.image_arrival_times_s):
        us = np.round(times * 1e6).astype(np.int64)
        assert np.array_equal(us / 1e6, times)
        assert np.array_equal((us * 1000) / 1e9, times)  # whole ns too: a bag of it agrees
    camera = run.camera_intrinsics
    assert camera_from_text(camera_text(camera)) == camera


def _split(events):
    events = list(events)
    readings = [e for e in events if hasattr(e, "positions")]
    images = [e for e in events if hasattr(e, "depth")]
    return readings, images


def test_the_log_holds_the_run(run, log, apollo):
    source = LcmLogSource(log, apollo.robot_joint_names, run.camera_intrinsics)
    assert (source.status_channel, source.status_type) == ("IIWA_STATUS", "iiwa")
    assert source.base_us == DEFAULT_BASE_US + round(run.reading_times_s[0] * 1e6)
    assert source.base_ns == source.base_us * 1000
    readings, images = _split(source.events())
    assert len(readings) == len(run.reading_times_s)
    assert len(images) == len(run.image_capture_times_s) == source.num_images
    np.testing.assert_array_equal([r.time_s for r in readings],
                                  run.reading_times_s - run.reading_times_s[0])
    np.testing.assert_array_equal(np.stack([r.positions for r in readings]), run.readings_rad)
    order, _ = run.cameras[0].arrival_order()
    for image, i in zip(images, order):
        assert image.capture_s == run.image_capture_times_s[i]
        assert image.arrival_s == run.image_arrival_times_s[i]
        np.testing.assert_array_equal(image.depth, run.depth_images_m[i].astype(np.float32))


@pytest.mark.parametrize("depth_type", ["float32", "uint16"])
def test_compressed_and_millimetre_depth_read_back_as_written(run, apollo, tmp_path,
                                                              depth_type):
    path = tmp_path / "zlib.lcmlog"
    write_run_lcm_log(run, path, depth_type=depth_type, compress=True)
    source = LcmLogSource(path, apollo.robot_joint_names, run.camera_intrinsics)
    _, images = _split(source.events())
    order, _ = run.cameras[0].arrival_order()
    for image, i in zip(images, order, strict=True):
        written = np.asarray(run.depth_images_m[i], np.float32)
        if depth_type == "uint16":
            written = millimetres(written)
            assert image.depth.dtype == np.uint16 and (image.depth > 0).any()
        np.testing.assert_array_equal(image.depth, written)


def test_round_trip_gives_the_same_estimates(run, log, apollo, tmp_path, capsys):
    """``track --run`` and ``track --lcm-log`` on the same µs-stamped run."""
    run_file = run.save(tmp_path / "run.npz")
    robot = tmp_path / "robot.yaml"
    robot.write_text(run.robot_config_yaml)
    params = tmp_path / "params.yaml"
    params.write_text(tracker_params_to_yaml(small_params()))
    code, _, err = run_cli(["track", "--run", str(run_file), "--params", str(params),
                            "--out", str(tmp_path / "run")], capsys)
    assert code == 0, err
    code, out, err = run_cli(["track", "--lcm-log", str(log), "--robot", str(robot),
                              "--camera", camera_text(run.camera_intrinsics),
                              "--params", str(params), "--out", str(tmp_path / "lcm")],
                             capsys)
    assert code == 0, err
    assert "IIWA_STATUS (lcmt_iiwa_status), DRAKE_RGBD_CAMERA_IMAGES" in out
    direct = json.loads((tmp_path / "run" / "report.json").read_text())
    from_log = json.loads((tmp_path / "lcm" / "report.json").read_text())
    assert direct["counts"]["images_applied"] > 5
    assert direct["counts"] == from_log["counts"]
    assert from_log["input"]["status_type"] == "lcmt_iiwa_status"
    a = read_estimates_csv(tmp_path / "run" / "estimates.csv")
    b = read_estimates_csv(tmp_path / "lcm" / "estimates.csv")
    assert len(a["t_s"]) == len(run.reading_times_s)
    for column in a:
        if column in ("health", "t0_s"):
            continue
        np.testing.assert_allclose(b[column], a[column], rtol=0, atol=1e-9, err_msg=column)
    assert (a["health"] == b["health"]).all()
    assert b["t0_s"][0] == stamp_text(DEFAULT_BASE_US * 1000, run.reading_times_s[0])


def _write(path, events):
    """A log of (log utime, channel, bytes)."""
    out = lcm.EventLog(str(path), "w")
    for utime, channel, data in events:
        out.write_event(utime, channel, data)
    out.close()
    return path


def _image(utime, depth, **fields):
    image = depth_image_message(utime, depth)
    for name, value in fields.items():
        setattr(image, name, value)
    return image_array_message(utime, [image])


CAMERA = camera_from_text("8x6:10.0,10.0,4.0,3.0")


def test_bad_logs_are_named(apollo, tmp_path):
    names = apollo.robot_joint_names
    n = len(names)
    t0 = DEFAULT_BASE_US
    good = [(t0, "IIWA_STATUS", status_message(t0, np.zeros(n))),
            (t0, "DRAKE_RGBD_CAMERA_IMAGES", _image(t0, np.ones((6, 8), np.float32))),
            (t0 + 5000, "IIWA_STATUS", status_message(t0 + 5000, np.zeros(n)))]
    ok = _write(tmp_path / "ok.lcmlog", good)
    assert LcmLogSource(ok, names, CAMERA).num_images == 1
    with pytest.raises(ValueError, match="missing.lcmlog does not exist"):
        LcmLogSource(tmp_path / "missing.lcmlog", names, CAMERA)
    data = ok.read_bytes()
    first = _write(tmp_path / "first.lcmlog", good[:1]).stat().st_size
    two = _write(tmp_path / "two.lcmlog", good[:2]).stat().st_size
    for name, content, message in (
            ("empty", b"", "is empty"),
            ("text", b"this is not an lcm log at all",
             "no event can be read at byte 0 of 29 .*not an lcm-logger file"),
            ("truncated", data[:-7], f"no event can be read at byte {two} .*after 2 events"),
            ("damaged", data[:100] + b"junk" + data[100:], "no event can be read at byte 0 "),
            # lcm.EventLog refuses the event before the junk: the log stops there.
            ("garbage", data[:two] + b"junk" + data[two:],
             f"no event can be read at byte {first} .*after 1 events")):
        (tmp_path / f"{name}.lcmlog").write_bytes(content)
        with pytest.raises(ValueError, match=f"{name}.lcmlog .*{message}"):
            LcmLogSource(tmp_path / f"{name}.lcmlog", names, CAMERA)
    with pytest.raises(ValueError, match=r"no channel 'CAMERA'.*DRAKE_RGBD_CAMERA_IMAGES "
                                         r"\(1\), IIWA_STATUS \(2\)"):
        LcmLogSource(ok, names, CAMERA, image_channel="CAMERA")
    with pytest.raises(ValueError, match="0 of the channels IIWA_STATUS, PANDA_STATUS"):
        LcmLogSource(_write(tmp_path / "renamed.lcmlog",
                            [(t, "ARM", d) if c == "IIWA_STATUS" else (t, c, d)
                             for t, c, d in good]), names, CAMERA)
    with pytest.raises(ValueError, match=f"hold 7 joints, the model has {n} robot joints"):
        LcmLogSource(_write(tmp_path / "seven.lcmlog", [
            (t0, "IIWA_STATUS", status_message(t0, np.zeros(7))), *good[1:]]), names, CAMERA)
    with pytest.raises(ValueError, match="are not lcmt_panda_status .*: lcmt_iiwa_status"):
        LcmLogSource(ok, names, CAMERA, status_type="panda")
    with pytest.raises(ValueError, match="the first message on IIWA_STATUS cannot be decoded"):
        LcmLogSource(_write(tmp_path / "cut.lcmlog", [
            (t0, "IIWA_STATUS", good[0][2][:30]), *good[1:]]), names, CAMERA)
    with pytest.raises(ValueError, match="are not lcmt_iiwa_status or lcmt_panda_status"):
        LcmLogSource(_write(tmp_path / "other.lcmlog", [
            (t0, "IIWA_STATUS", b"\x00" * 40), *good[1:]]), names, CAMERA)


def test_bad_messages_are_skipped_and_counted(apollo, tmp_path):
    names = apollo.robot_joint_names
    n = len(names)
    t0 = DEFAULT_BASE_US
    events = []
    for k in range(20):
        t = t0 + k * 10_000 - (25_000 if k == 12 else 0)  # reading 12's stamp jumps back
        positions = np.zeros(n - 1 if k == 5 else n)
        events.append((t0 + k * 10_000, "IIWA_STATUS", status_message(t, positions)))
    events[7] = (events[7][0], "IIWA_STATUS", events[7][2][:30])  # cut short
    colour = depth_image_message(t0, np.ones((6, 8), np.float32))
    colour.pixel_format = lcmt_image.PIXEL_FORMAT_RGB
    events += [
        (t0 + 50_000, "DRAKE_RGBD_CAMERA_IMAGES", image_array_message(t0, [colour])),
        (t0 + 60_000, "DRAKE_RGBD_CAMERA_IMAGES", _image(t0, np.ones((5, 8), np.float32))),
        (t0 + 70_000, "DRAKE_RGBD_CAMERA_IMAGES", _image(t0, np.ones((6, 8), np.float32),
                                                         compression_method=1)),
        (t0 + 80_000, "DRAKE_RGBD_CAMERA_IMAGES", _image(t0, np.ones((6, 8), np.float32),
                                                         channel_type=7)),
        (t0 + 90_000, "OTHER", b"ignored")]
    events.sort(key=lambda e: e[0])
    path = _write(tmp_path / "faults.lcmlog", events)
    report = track_lcm_log(LcmLogSource(path, names, CAMERA), apollo, small_params(),
                           tmp_path / "out", progress=False)
    counts = report["counts"]
    assert counts["source_skipped"] == {"status messages with another joint count": 1,
                                        "undecodable messages": 1,
                                        "depth images not usable": 3,
                                        "depth images of another size": 1}
    assert counts["readings"] == 18
    assert sum(counts["readings_skipped"].values()) >= 1  # the stamp that jumps back
    assert counts["estimates"] == 18 - sum(counts["readings_skipped"].values())


def test_panda_status_is_read(apollo, tmp_path):
    names = apollo.robot_joint_names
    message = lcmt_panda_status()
    message.utime, message.num_joints = DEFAULT_BASE_US, len(names)
    for field in ("joint_position", "joint_position_desired", "joint_velocity",
                  "joint_velocity_desired", "joint_acceleration_desired", "joint_torque",
                  "joint_torque_desired", "joint_torque_external"):
        setattr(message, field, list(np.arange(len(names)) * (field == "joint_position")))
    path = _write(tmp_path / "panda.lcmlog", [
        (DEFAULT_BASE_US, "PANDA_STATUS", message.encode()),
        (DEFAULT_BASE_US, "DRAKE_RGBD_CAMERA_IMAGES",
         _image(DEFAULT_BASE_US, np.ones((6, 8), np.float32)))])
    source = LcmLogSource(path, names, CAMERA)
    assert (source.status_channel, source.status_type) == ("PANDA_STATUS", "panda")
    readings, images = _split(source.events())
    np.testing.assert_array_equal(readings[0].positions, np.arange(len(names)))
    assert len(images) == 1 and images[0].capture_s == 0.0


def test_without_the_extra_the_error_names_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "lcm", None)
    with pytest.raises(ImportError, match="needs the 'lcm' extra: pip install "
                                          r"'drake_tracker\[lcm\]'"):
        require_lcm()


def test_lcm_flags_are_one_line_errors(run, log, tmp_path, capsys):
    robot = tmp_path / "robot.yaml"
    robot.write_text(run.robot_config_yaml)
    code, _, err = run_cli(["track", "--lcm-log", str(log), "--robot", str(robot)], capsys)
    assert_one_line_error(code, err, "--lcm-log needs --camera WIDTHxHEIGHT:fx,fy,cx,cy")
    code, _, err = run_cli(["track", "--lcm-log", str(log), "--robot", str(robot),
                            "--camera", "80x60"], capsys)
    assert_one_line_error(code, err, "camera '80x60' is not WIDTHxHEIGHT:fx,fy,cx,cy")
    code, _, err = run_cli(["track", "--run", "x.npz", "--camera", "8x6:1,1,1,1"], capsys)
    assert_one_line_error(code, err, "--camera: only with --lcm-log")
    code, _, err = run_cli(["track", "--lcm-log", str(log), "--camera", "8x6:1,1,1,1"],
                           capsys)
    assert_one_line_error(code, err, "--lcm-log needs --robot ROBOT.yaml")
    code, _, err = run_cli(["track", "--lcm-log", str(tmp_path / "none.lcmlog"), "--robot",
                            str(robot), "--camera", "8x6:1,1,1,1"], capsys)
    assert_one_line_error(code, err, "none.lcmlog does not exist")
    code, _, err = run_cli(["track", "--lcm-log", str(log), "--robot", str(robot),
                            "--camera", "8x6:1,1,1,1", "--image-channel", "RGB"], capsys)
    assert_one_line_error(code, err, "no channel 'RGB' (--image-channel)", "IIWA_STATUS (120)")
    code, _, err = run_cli(["record", "--lcm-log", str(log)], capsys)
    assert_one_line_error(code, err, "exists: not overwritten")
