"""``drake-tracker record``, ``track`` and ``calibrate-cameras``: data in and out."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from drake_tracker.cli.args import (
    PARAMS_HELP,
    SCENARIO_HELP,
    UsageError,
    check_new_file,
    check_new_log,
    check_out_dir,
    check_params_for_model,
    load_params_arg,
    load_run_arg,
    named_flags,
    positive_int,
    positive_seconds,
    resolve_scenario,
    scenario_name,
)
from drake_tracker.cli.lcm_args import (
    add_lcm_track_arguments,
    check_lcm_flags,
    open_lcm_log,
    track_lcm_log_command,
)

if TYPE_CHECKING:
    from drake_tracker.io.bag_source import BagTopics
    from drake_tracker.robot.model import TrackerModel


def add_record(sub: argparse._SubParsersAction) -> None:
    """The ``record`` subcommand."""
    p = sub.add_parser(
        "record", help="simulate a scenario and write a recorded run (.npz), a bag or an "
                       "LCM log",
        description="Simulates a scenario and writes every encoder reading, every depth "
                    "image (subsampled) and the ground truth to one .npz file (format in "
                    "drake_tracker/io/recording.py), to replay with 'drake-tracker track', "
                    "and/or to a ROS 2 MCAP bag (--bag; needs the 'ros' extra), with the "
                    "truth on its own topics and the true camera frames on /tf "
                    "(drake_tracker/io/run_bag.py), and/or to an "
                    "lcm-logger file (--lcm-log; needs the 'lcm' extra; Drake's "
                    "IIWA_STATUS and DRAKE_RGBD_CAMERA_IMAGES channels, no truth: "
                    "drake_tracker/io/run_lcm_log.py). With --lcm-log every stamp is "
                    "rounded to whole microseconds, in all the files written, and the "
                    "camera is printed as the --camera argument of 'track --lcm-log'.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  drake-tracker record --scenario arm/time-varying --duration 5 "
               "--out out/arm.npz\n  drake-tracker record --duration 5 --bag out/arm.mcap\n"
               "  drake-tracker record --duration 5 --out out/arm.npz --lcm-log "
               "out/arm.lcmlog")
    p.add_argument("--scenario", default="s-full-arm/constant", help=SCENARIO_HELP)
    p.add_argument("--out", default=None, metavar="FILE.npz", help="recorded run to write")
    p.add_argument("--bag", default=None, metavar="FILE.mcap",
                   help="ROS 2 MCAP bag to write (a new file)")
    p.add_argument("--lcm-log", default=None, metavar="FILE",
                   help="lcm-logger file to write (a new file)")
    p.add_argument("--duration", type=positive_seconds, default=None, metavar="SECONDS",
                   help="simulate this long instead of the scenario's duration")
    p.add_argument("--image-stride", type=positive_int, default=8, metavar="N",
                   help="store every N-th pixel of each image row and column "
                        "(default: %(default)s)")

    def run(args):
        if args.out is None and args.bag is None and args.lcm_log is None:
            raise UsageError("say where to write the run: --out FILE.npz, --bag FILE.mcap "
                             "and/or --lcm-log FILE")
        resolve_scenario(args.scenario)
        args.scenario = scenario_name(args.scenario)
        if args.out is not None:
            check_new_file(args.out, ".npz")
        if args.bag is not None:
            from drake_tracker.io.ros_messages import require_rosbags

            check_new_log(args.bag, "bag", require_rosbags, ".mcap")
        if args.lcm_log is not None:
            from drake_tracker.io.lcm_messages import require_lcm

            check_new_log(args.lcm_log, "LCM log", require_lcm)
        from drake_tracker.sim.record import run_record

        return run_record(args)

    p.set_defaults(func=run)


def add_track(sub: argparse._SubParsersAction) -> None:
    """The ``track`` subcommand."""
    p = sub.add_parser(
        "track", help="track a recorded run, a ROS bag or an LCM log with the offline "
                      "tracker",
        description="Feeds a recorded run (--run), a ROS bag (--bag: ROS 1 .bag, ROS 2 "
                    "bag folder or .mcap; needs the 'ros' extra) or an lcm-logger file "
                    "(--lcm-log: Drake's lcmt_iiwa_status or lcmt_panda_status and "
                    "lcmt_image_array depth; needs the 'lcm' extra; see "
                    "drake_tracker/io/lcm_log.py) to the offline tracker in "
                    "the order a live tracker receives them. With --out it writes "
                    "estimates.csv (one row per reading), estimates.mcap and report.json "
                    "(counts, and error percentiles when the input has a truth): see "
                    "drake_tracker/io/estimates_out.py.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  drake-tracker record --duration 5 --out out/run.npz\n"
               "  drake-tracker track --run out/run.npz --out out/tracked\n"
               "  drake-tracker track --bag robot.mcap --robot robot.yaml --out out/bag\n"
               "  drake-tracker track --lcm-log robot.lcmlog --robot robot.yaml "
               "--camera 640x480:615.0,615.0,319.5,239.5 --out out/lcm")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--run", metavar="FILE.npz",
                        help="recorded run, written by 'drake-tracker record'")
    source.add_argument("--bag", metavar="PATH",
                        help="ROS 1 .bag, ROS 2 bag folder (sqlite3 or MCAP) or .mcap file")
    source.add_argument("--lcm-log", metavar="FILE", help="lcm-logger file")
    add_bag_track_arguments(p)
    add_lcm_track_arguments(p)
    p.add_argument("--params", default=None, metavar="YAML", help=PARAMS_HELP)
    p.add_argument("--out", default=None, help="folder for estimates.csv, estimates.mcap "
                   "and report.json (optional)")

    def run(args):
        params = load_params_arg(args.params)
        if args.out:
            check_out_dir(args.out)
        check_lcm_flags(args)
        if args.bag is not None:
            return _track_bag(args, params)
        if args.lcm_log is not None:
            return track_lcm_log_command(args, params, robot_model(args.robot, "--lcm-log"))
        if args.robot is not None:
            raise UsageError("--robot is for --bag and --lcm-log: a recorded run carries "
                             "its robot")
        recorded = load_run_arg(args.run)
        from drake_tracker.io.replay import model_for_run, run_track

        try:
            model = model_for_run(recorded)
        except ValueError as err:
            raise UsageError(f"'{args.run}': its robot model: {err}") from None
        if args.params:
            check_params_for_model(params, model, f"parameter file '{args.params}'")
        return run_track(args, run=recorded, params=params, model=model)

    p.set_defaults(func=run)


def add_calibrate(sub: argparse._SubParsersAction) -> None:
    """The ``calibrate-cameras`` subcommand."""
    p = sub.add_parser(
        "calibrate-cameras", help="each camera's mounting error from a recorded run of "
                                  "several cameras",
        description="Fits every camera's six offsets (its mounting error) to the images of "
                    "all cameras in a window where they see the arm, together (the window "
                    "given, or found: the first two seconds in which each camera has 3 "
                    "images that show the arm): the tracker replays the recording to the "
                    "window's "
                    "end and its estimate starts the fit "
                    "(drake_tracker/io/calibrate_run.py). Writes the tracker parameters "
                    "'camera_offsets', held ('estimate_camera_offset: false'), for "
                    "--params of later runs of the same cell (see "
                    "docs/guides/several_cameras.md).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n  drake-tracker record --scenario in-out-in-2cam/none --duration 3 "
               "--out out/cal.npz\n  drake-tracker calibrate-cameras --run out/cal.npz "
               "--out out/cameras.yaml\n  drake-tracker track --run out/run.npz "
               "--params out/cameras.yaml")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--run", metavar="FILE.npz",
                        help="recorded run of several cameras, written by 'drake-tracker "
                             "record'")
    source.add_argument("--bag", metavar="PATH", help="ROS bag with a depth topic per "
                        "camera (--depth-topic NAME=TOPIC, --robot; as 'track --bag')")
    source.add_argument("--lcm-log", metavar="FILE", help="lcm-logger file with a channel "
                        "per camera (--camera NAME=WxH:..., --robot; as 'track --lcm-log')")
    add_bag_track_arguments(p)
    add_lcm_track_arguments(p)
    p.add_argument("--out", required=True, metavar="FILE.yaml",
                   help="the tracker parameters to write (camera_offsets)")
    p.add_argument("--from", dest="start_s", type=float, default=None, metavar="SECONDS",
                   help="the window's start, in the recording's time (with --to; default: "
                        "the first --window-s seconds, after every camera has said "
                        "'tracking', in which each camera has 3 images that show the "
                        "arm)")
    p.add_argument("--to", dest="end_s", type=positive_seconds, default=None,
                   metavar="SECONDS", help="the window's end (with --from)")
    p.add_argument("--window-s", type=positive_seconds, default=2.0, metavar="SECONDS",
                   help="the length of the window found without --from and --to "
                        "(default: 2)")
    p.add_argument("--images-per-camera", type=positive_int, default=10,
                   help="images of each camera the fit scores, spread over the window "
                        "(default: 10)")
    p.add_argument("--evaluations", type=positive_int, default=8000,
                   help="the fit's evaluations of the window's likelihood (default: 8000)")
    p.add_argument("--params", default=None, metavar="YAML", help=PARAMS_HELP)

    def run(args):
        params = load_params_arg(args.params)
        out = check_new_file(args.out, ".yaml")
        if (args.start_s is None) != (args.end_s is None):
            raise UsageError("--from and --to go together (without them the window is "
                             "found)")
        window = dict(start_s=args.start_s, end_s=args.end_s, window_s=args.window_s,
                      images_per_camera=args.images_per_camera, evaluations=args.evaluations)
        check_lcm_flags(args)
        try:
            if args.bag is not None:
                result = _calibrate_source(*_open_bag(args, params), params, window)
            elif args.lcm_log is not None:
                model = robot_model(args.robot, "--lcm-log")
                result = _calibrate_source(model, open_lcm_log(args, params, model), params,
                                           window)
            else:
                if args.robot is not None:
                    raise UsageError("--robot is for --bag and --lcm-log: a recorded run "
                                     "carries its robot")
                from drake_tracker.io.calibrate_run import calibrate_run

                result = calibrate_run(load_run_arg(args.run), params, **window)
        except ValueError as err:
            raise UsageError(f"'{args.bag or args.lcm_log or args.run}': {err}") from None
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(result.params_yaml())
        print(result.params_yaml(), end="")
        print(f"wrote {out}")
        return 0

    p.set_defaults(func=run)


def add_bag_track_arguments(p: argparse.ArgumentParser) -> None:
    """``--robot`` and the topic flags of ``--bag`` (``track``, ``calibrate-cameras``:
    read by ``_open_bag``)."""
    p.add_argument("--robot", default=None, metavar="ROBOT.yaml",
                   help="with --bag or --lcm-log: the robot (a RobotConfig YAML, as "
                        "drake_tracker.robot.model.load_robot_config reads it, or a "
                        "shipped preset: apollo, arm6)")
    p.add_argument("--joint-topic", default=None, help="with --bag: the JointState topic "
                   "(default: the only one)")
    p.add_argument("--depth-topic", default=None, action="append",
                   metavar="[NAME=]TOPIC",
                   help="with --bag: the depth Image topic (default: the only one); "
                        "repeated as NAME=TOPIC, several depth cameras, each the model's "
                        "camera NAME (RobotConfig.cameras)")
    p.add_argument("--camera-info-topic", default=None, action="append",
                   metavar="[NAME=]TOPIC",
                   help="with --bag: the CameraInfo topic (default: the only one); as "
                        "NAME=TOPIC, camera NAME's (default: the only one beside its depth "
                        "topic)")


def _calibrate_source(model: TrackerModel, source, params, window: dict):
    """``calibrate-cameras`` on an open bag or LCM log (``--bag``, ``--lcm-log``, opened
    as ``track`` opens them): its events and camera models; the source is closed."""
    from drake_tracker.io.calibrate_run import calibrate_cameras

    try:
        return calibrate_cameras(source.events(), model, source.camera_models(), params,
                                 **window)
    finally:
        source.close()


def _open_bag(args, params):
    """The robot (``--robot``) and the open ``BagSource`` of ``--bag`` with the topic
    flags of ``track`` and ``calibrate-cameras``; a UsageError naming what is wrong."""
    model = robot_model(args.robot, "--bag")
    try:
        from drake_tracker.io.bag_source import BagSource, check_camera_topics
    except ImportError as err:
        raise UsageError(str(err)) from None
    if args.params:
        check_params_for_model(params, model, f"parameter file '{args.params}'")
    try:
        topics = bag_topics(args.joint_topic, args.depth_topic, args.camera_info_topic)
        check_camera_topics(topics.cameras, model.camera_names)
        return model, BagSource(args.bag, model.robot_joint_names, topics)
    except ValueError as err:
        raise UsageError(str(err)) from None


def robot_model(path: str | None, flag: str) -> TrackerModel:
    """The TrackerModel of ``--robot path`` (a RobotConfig YAML file, or the name of a
    shipped preset: ``apollo``, ``arm6``), which ``flag`` needs; a UsageError naming
    what is wrong."""
    from pathlib import Path

    from drake_tracker.robot.model import ROBOT_PRESETS

    if path is None:
        raise UsageError(f"{flag} needs --robot ROBOT.yaml: the robot the log was recorded "
                         f"on (or a preset: {', '.join(sorted(ROBOT_PRESETS))})")
    if path in ROBOT_PRESETS and not Path(path).is_file():
        from drake_tracker.robot.model import build_tracker_model, robot_preset

        return build_tracker_model(robot_preset(path))
    if not Path(path).is_file():
        raise UsageError(f"robot file '{path}' does not exist (presets: "
                         f"{', '.join(sorted(ROBOT_PRESETS))})")
    try:
        from drake_tracker.robot.model import build_tracker_model, load_robot_config

        return build_tracker_model(load_robot_config(Path(path).read_text()))
    except ImportError as err:
        raise UsageError(str(err)) from None
    except (ValueError, RuntimeError) as err:
        raise UsageError(f"robot file '{path}': {err}") from None


def _track_bag(args, params) -> int:
    model, source = _open_bag(args, params)
    from drake_tracker.io.track_files import print_report, track_bag

    try:
        report = track_bag(source, model, params, args.out)
    except ValueError as err:
        raise UsageError(str(err)) from None
    print_report(report)
    if args.out:
        print(f"wrote {args.out}/: " + ", ".join(report["files"] + ["report.json"]))
    return 0


def bag_topics(joints: str | None, depth: list[str] | None, info: list[str] | None
               ) -> BagTopics:
    """The ``BagTopics`` of ``--joint-topic``, ``--depth-topic`` and
    ``--camera-info-topic``: one camera (``TOPIC``, each flag at most once) or several
    (``NAME=TOPIC``, a camera-info topic for a named camera only). ValueError naming
    what is wrong."""
    from drake_tracker.io.bag_source import BagTopics, CameraTopics

    depth, info = depth or [], info or []
    named = named_flags(depth, info, ("--depth-topic", "--camera-info-topic"), "TOPIC")
    if named is None:
        return BagTopics(joints, depth[0] if depth else None, info[0] if info else None)
    pairs, infos = named
    return BagTopics(joints, cameras=tuple(CameraTopics(name, topic, infos.get(name))
                                           for name, topic in pairs))
