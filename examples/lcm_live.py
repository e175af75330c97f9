"""Tracking live from LCM: Drake's own LCM systems around ``AddTracker``.

Run: python examples/lcm_live.py --robot ROBOT.yaml --camera WxH:fx,fy,cx,cy
         [--encoder-period 0.001] [--duration 60] [--lcm-url udpm://...]
     (several cameras: --camera NAME=WxH:fx,fy,cx,cy for each of the robot's cameras)

The Diagram is what a Drake robot on LCM already has:
  * ``DrakeLcm`` and an ``LcmInterfaceSystem``, which hands the received messages to
    the subscribers as the Simulator advances (in real time here);
  * ``IIWA_STATUS`` (``lcmt_iiwa_status``) through an ``LcmSubscriberSystem`` into
    Drake's ``IiwaStatusReceiver``: ``position_measured`` (the robot joints, in the
    model's ``robot_joint_names`` order: ``num_joints`` of them) and ``time_measured``
    (the status's ``utime`` in s) are the tracker's readings and their stamp;
  * ``DRAKE_RGBD_CAMERA_IMAGES`` (``lcmt_image_array``) through an
    ``LcmSubscriberSystem`` into ``LcmImageArrayToDepth``
    (``drake_tracker/systems/lcm_adapters.py``): the depth image in metres and its
    capture time (the image's ``header.utime`` in s); with several cameras, one of each
    per camera on ``DRAKE_RGBD_CAMERA_IMAGES_<name>``, the channel Drake's
    ``ApplyCameraConfig`` publishes a named camera on, into ``AddTracker(cameras=...)``;
  * ``AddTracker``, and an ``LcmPublisherSystem`` sending the hand pose in the estimated
    camera frame (``X_CE``) on ``TRACKER_HAND_POSE`` as an ``lcmt_viewer_draw`` of one
    link, ``end_effector``, once per encoder period. ``lcmt_viewer_draw`` is Drake's
    message for the poses of named frames (position and quaternion, self-describing,
    shown as it is by ``lcm-spy`` and Drake's viewers); its float32 fields hold the
    pose to well under a micrometre, a thousandth of the tracker's accuracy.
    (``lcmt_robot_state`` would carry joint angles, not the pose a visual servo needs.)

The stamps are the robot's: the tracker needs the status's and the images' on one clock,
and the encoder period of the status messages.
"""

import argparse
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from drake import lcmt_iiwa_status, lcmt_image_array, lcmt_viewer_draw
from pydrake.lcm import DrakeLcm, DrakeLcmInterface
from pydrake.manipulation import IiwaStatusReceiver
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem

from drake_tracker import AddTracker, TrackerParams, TrackerSystems
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.io.lcm_messages import DRAKE_RGBD_CAMERA_IMAGES, IIWA_STATUS, camera_channel
from drake_tracker.robot.model import TrackerModel
from drake_tracker.systems.add_tracker import TrackerCamera
from drake_tracker.systems.lcm_adapters import LcmImageArrayToDepth, PoseToLcmViewerDraw

#: The channel the hand pose estimate is published on.
HAND_POSE_CHANNEL = "TRACKER_HAND_POSE"


@dataclass
class LcmTracker:
    """The built Diagram and the systems a caller reads."""

    diagram: Diagram
    tracker: TrackerSystems
    #: The (first) camera's image adapter.
    images: LcmImageArrayToDepth
    status: IiwaStatusReceiver
    #: Each camera's image adapter by name (several cameras).
    images_by_camera: dict[str, LcmImageArrayToDepth] = field(default_factory=dict)


def build(lcm: DrakeLcmInterface, model: TrackerModel,
          camera: CameraIntrinsics | Mapping[str, CameraIntrinsics],
          encoder_period_s: float, params: TrackerParams | None = None,
          status_channel: str = IIWA_STATUS,
          image_channel: str | Mapping[str, str] | None = None,
          pose_channel: str = HAND_POSE_CHANNEL,
          pose_lcm: DrakeLcmInterface | None = None) -> LcmTracker:
    """The Diagram (see the module) on ``lcm``; the hand pose goes out on ``pose_lcm``
    (default: ``lcm``), e.g. another LCM URL than the robot's. ``camera``: the one
    camera's intrinsics (its images on ``image_channel``, default
    ``DRAKE_RGBD_CAMERA_IMAGES``), or several cameras' by the model's camera names (each
    on ``image_channel[name]``, default ``DRAKE_RGBD_CAMERA_IMAGES_<name>``)."""
    builder = DiagramBuilder()
    builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    # IiwaStatusReceiver is C++: it takes the C++ message, hence the C++ serializer.
    status_in = builder.AddNamedSystem("status_subscriber", LcmSubscriberSystem.Make(
        status_channel, lcmt_iiwa_status, lcm, use_cpp_serializer=True))
    status = builder.AddNamedSystem("status_receiver",
                                    IiwaStatusReceiver(num_joints=len(model.robot_joint_names)))
    builder.Connect(status_in.get_output_port(), status.get_input_port())
    several = isinstance(camera, Mapping)
    cameras = dict(camera) if several else {"": camera}
    channels = dict(image_channel) if isinstance(image_channel, Mapping) else {}
    adapters = {}
    for name, intrinsics in cameras.items():
        suffix = f"_{name}" if several else ""
        channel = (channels.get(name, camera_channel(name)) if several
                   else image_channel or DRAKE_RGBD_CAMERA_IMAGES)
        images_in = builder.AddNamedSystem(f"image_subscriber{suffix}",
                                           LcmSubscriberSystem.Make(channel, lcmt_image_array,
                                                                    lcm))
        adapters[name] = builder.AddNamedSystem(
            f"image_array_to_depth{suffix}",
            LcmImageArrayToDepth(width=intrinsics.width, height=intrinsics.height))
        builder.Connect(images_in.get_output_port(),
                        adapters[name].get_image_array_input_port())
    readings = dict(params=params, encoder_period_s=encoder_period_s,
                    measured_position=status.get_position_measured_output_port(),
                    measurement_time=status.get_time_measured_output_port())
    if several:
        tracker = AddTracker(builder, model=model, **readings, cameras=[
            TrackerCamera(name, cameras[name], a.get_depth_image_output_port(),
                          a.get_image_time_output_port()) for name, a in adapters.items()])
    else:
        images = adapters[""]
        tracker = AddTracker(builder, model=model, camera=camera, **readings,
                             depth=images.get_depth_image_output_port(),
                             image_time=images.get_image_time_output_port())
    to_message = builder.AddNamedSystem("hand_pose_to_lcm", PoseToLcmViewerDraw(
        name="end_effector"))
    builder.Connect(tracker.X_CE, to_message.get_pose_input_port())
    publisher = builder.AddNamedSystem("hand_pose_publisher", LcmPublisherSystem.Make(
        pose_channel, lcmt_viewer_draw, pose_lcm or lcm, publish_period=encoder_period_s,
        publish_offset=0.75 * encoder_period_s))
    builder.Connect(to_message.get_message_output_port(), publisher.get_input_port())
    return LcmTracker(builder.Build(), tracker, next(iter(adapters.values())), status,
                      adapters if several else {})


def main() -> None:
    """Tracks from the LCM bus in real time for ``--duration`` s."""
    from drake_tracker.cli.lcm_args import lcm_cameras
    from drake_tracker.robot.model import build_tracker_model, load_robot_config

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", required=True, help="RobotConfig YAML")
    parser.add_argument("--camera", required=True, action="append",
                        help="WxH:fx,fy,cx,cy (pixels); NAME=WxH:... for each of several")
    parser.add_argument("--encoder-period", type=float, default=0.001, help="s")
    parser.add_argument("--duration", type=float, default=60.0, help="s")
    parser.add_argument("--lcm-url", default=None, help="default: DrakeLcm's")
    args = parser.parse_args()
    model = build_tracker_model(load_robot_config(Path(args.robot).read_text()))
    lcm = DrakeLcm(args.lcm_url) if args.lcm_url else DrakeLcm()
    cameras = lcm_cameras(args.camera, None)
    live = build(lcm, model, cameras[0].intrinsics if cameras[0].name is None else
                 {c.name: c.intrinsics for c in cameras}, args.encoder_period)
    simulator = Simulator(live.diagram)
    simulator.set_target_realtime_rate(1.0)
    simulator.AdvanceTo(args.duration)
    skipped = ({name: a.skipped for name, a in live.images_by_camera.items()}
               or live.images.skipped)
    print(f"published {HAND_POSE_CHANNEL}; depth messages skipped: {skipped}")


if __name__ == "__main__":
    main()
