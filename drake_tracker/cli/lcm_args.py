"""The LCM arguments of ``drake-tracker track``, ``calibrate-cameras`` and ``record``
(``cli/io_commands.py``)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from drake_tracker.cli.args import UsageError, check_params_for_model, named_flags

if TYPE_CHECKING:
    from drake_tracker.core.sensors.camera import CameraIntrinsics
    from drake_tracker.io.lcm_log import LcmCamera, LcmLogSource
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

#: The flags that only go with ``--lcm-log`` (argparse dests).
LCM_TRACK_FLAGS = ("camera", "status_channel", "image_channel", "status_type")


def add_lcm_track_arguments(p: argparse.ArgumentParser) -> None:
    """Adds ``track``'s ``--camera``, ``--status-channel``, ``--image-channel`` and
    ``--status-type``."""
    p.add_argument("--camera", default=None, action="append",
                   metavar="[NAME=]WxH:fx,fy,cx,cy",
                   help="with --lcm-log: the depth camera's intrinsics in pixels, e.g. "
                        "640x480:615.0,615.0,319.5,239.5 (an lcmt_image carries none; "
                        "'record --lcm-log' prints its camera in this form); repeated as "
                        "NAME=WxH:..., several depth cameras, each the model's camera NAME "
                        "(RobotConfig.cameras), its images on DRAKE_RGBD_CAMERA_IMAGES_NAME")
    p.add_argument("--status-channel", default=None, help="with --lcm-log: the status "
                   "channel (default: IIWA_STATUS or PANDA_STATUS, whichever the log has)")
    p.add_argument("--image-channel", default=None, action="append",
                   metavar="[NAME=]CHANNEL",
                   help="with --lcm-log: the lcmt_image_array channel (default: "
                        "DRAKE_RGBD_CAMERA_IMAGES); as NAME=CHANNEL, camera NAME's "
                        "(default: DRAKE_RGBD_CAMERA_IMAGES_NAME)")
    p.add_argument("--status-type", default=None, choices=("auto", "iiwa", "panda"),
                   help="with --lcm-log: the status message type (default: auto, by the "
                        "messages' fingerprint)")


def lcm_cameras(cameras: list[str], channels: list[str] | None) -> list[LcmCamera]:
    """The cameras of ``--camera`` and ``--image-channel``: one camera (``WxH:...``,
    each flag at most once), named None, on its channel (default
    ``DRAKE_RGBD_CAMERA_IMAGES``), or several (``NAME=WxH:...``, a channel for a named
    camera only, default ``DRAKE_RGBD_CAMERA_IMAGES_NAME``). ValueError naming what is
    wrong."""
    from drake_tracker.io.lcm_log import LcmCamera
    from drake_tracker.io.lcm_messages import DRAKE_RGBD_CAMERA_IMAGES, camera_channel

    named = named_flags(cameras, channels or [], ("--camera", "--image-channel"),
                        "WxH:fx,fy,cx,cy")
    if named is None:
        return [LcmCamera(None, channels[0] if channels else DRAKE_RGBD_CAMERA_IMAGES,
                          _intrinsics(cameras[0], None))]
    pairs, given = named
    return [LcmCamera(name, given.get(name, camera_channel(name)), _intrinsics(text, name))
            for name, text in pairs]


def _intrinsics(text: str, name: str | None) -> CameraIntrinsics:
    """``--camera``'s intrinsics ``text`` (of camera ``name``); a ValueError saying so."""
    from drake_tracker.io.lcm_messages import camera_from_text

    try:
        return camera_from_text(text)
    except ValueError as err:
        raise ValueError(f"--camera: {err}" if name is None else
                         f"--camera: camera '{name}': {err}") from None


def check_lcm_flags(args: argparse.Namespace) -> None:
    """The LCM flags go with ``--lcm-log`` only, and ``--lcm-log`` needs ``--camera``."""
    given = [f"--{k.replace('_', '-')}" for k in LCM_TRACK_FLAGS
             if getattr(args, k) is not None]
    if args.lcm_log is None and given:
        raise UsageError(f"{', '.join(given)}: only with --lcm-log")
    if args.lcm_log is not None and args.camera is None:
        raise UsageError("--lcm-log needs --camera WIDTHxHEIGHT:fx,fy,cx,cy (NAME=... for "
                         "each of several cameras): an LCM depth image does not carry its "
                         "intrinsics")


def open_lcm_log(args: argparse.Namespace, params: TrackerParams,
                 model: TrackerModel) -> LcmLogSource:
    """The open ``io/lcm_log.LcmLogSource`` of ``--lcm-log`` with its ``--camera``,
    ``--image-channel``, ``--status-channel`` and ``--status-type``; every fault a
    one-line UsageError."""
    try:
        cameras = lcm_cameras(args.camera, args.image_channel)
    except ValueError as err:
        raise UsageError(str(err)) from None
    if args.params:
        check_params_for_model(params, model, f"parameter file '{args.params}'")
    try:
        from drake_tracker.io.lcm_log import LcmLogSource, check_lcm_cameras

        if cameras[0].name is not None:
            check_lcm_cameras(cameras, model.camera_names)
        return LcmLogSource(args.lcm_log, model.robot_joint_names, cameras,
                            args.status_channel, status_type=args.status_type or "auto")
    except (ImportError, ValueError) as err:
        raise UsageError(" ".join(str(err).split())) from None


def track_lcm_log_command(args: argparse.Namespace, params: TrackerParams,
                          model: TrackerModel) -> int:
    """``drake-tracker track --lcm-log FILE --robot ROBOT.yaml --camera ...``: the log
    through ``io/track_files.track_lcm_log``; every fault a one-line UsageError."""
    source = open_lcm_log(args, params, model)
    try:
        from drake_tracker.io.track_files import print_report, track_lcm_log

        report = track_lcm_log(source, model, params, args.out)
    except (ImportError, ValueError) as err:
        raise UsageError(" ".join(str(err).split())) from None
    images = ", ".join(c.channel if c.name is None else f"{c.channel} ({c.name})"
                       for c in source.cameras)
    print(f"{args.lcm_log}: {source.status_channel} (lcmt_{source.status_type}_status), "
          f"{images} (lcmt_image_array)")
    print_report(report)
    if args.out:
        print(f"wrote {args.out}/: " + ", ".join(report["files"] + ["report.json"]))
    return 0
