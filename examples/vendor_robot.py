"""A vendor's robot as it ships: the Franka Panda of the PyPI package example-robot-data.

Run: pip install 'drake_tracker[meshes]' example-robot-data
     python examples/vendor_robot.py [--duration 2] [--share DIR]

The package installs the Panda's ROS description under
``<site-packages>/cmeel.prefix/share/example-robot-data``: a URDF whose meshes are
``package://example-robot-data/...`` URIs, DAE visuals and STL collision meshes, and no
camera. Nothing in it is edited: the RobotConfig names the package's folder, adds a
camera on the base (``panda_link0``) and uses the URDF's ``panda_hand_tcp`` as the end
effector. On the first load the meshes are converted to OBJ into the mesh cache.

The example prints the config as YAML (what a config file holds), checks the batched
renderer against Drake's RenderEngineVtk at the home pose the joint limits give, and
tracks the Panda with 8.6 deg encoder biases in the Diagram of
``track_in_your_diagram.py`` (a stock RgbdSensor, 2 cm / 2 deg off its nominal pose).
"""

import argparse
import sysconfig
import time
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_dump_typed
from track_in_your_diagram import RobotMotion, build, hand_errors_mm, print_errors

from drake_tracker import (
    FrameOffset,
    RobotConfig,
    TrackerParams,
    build_tracker_model,
    default_home_positions,
)
from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.core.renderer import make_renderer

PANDA_URDF = "package://example-robot-data/robots/panda_description/urdf/panda.urdf"
PANDA_ARM = [f"panda_joint{k}" for k in range(1, 8)]


def panda_config(share: Path) -> RobotConfig:
    """The Panda with a camera 1.5 m from its base, looking at its hand."""
    return RobotConfig(
        model_file=PANDA_URDF,
        camera_frame="camera_optical",
        end_effector_frame="panda_hand_tcp",
        package_paths={"example-robot-data": str(share)},
        added_frames={"camera_optical": FrameOffset(
            parent="panda_link0", xyz_m=[1.3, 0.5, 0.9], rpy_deg=[-112.74, 0.0, 117.76])})


def render_agreement(config: RobotConfig) -> None:
    """Batched renderer against RenderEngineVtk at the home pose, 80x60."""
    model = build_tracker_model(config)
    q = np.zeros((1, model.num_joints))
    q[0, :len(model.robot_joint_names)] = default_home_positions(
        model.plant, model.robot_joint_names)
    intrinsics = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
    batched = make_renderer(model, intrinsics, "batched")
    batched.render(q)  # compiles
    start = time.perf_counter()
    ours = batched.render(np.repeat(q, 20, axis=0))[0]
    per_image_us = 1e6 * (time.perf_counter() - start) / 20
    drake = make_renderer(model, intrinsics, "drake").render(q)[0]
    hit_ours, hit_drake = np.isfinite(ours), np.isfinite(drake)
    both = hit_ours & hit_drake
    print(f"robot pixels: batched {hit_ours.sum()}, Drake {hit_drake.sum()}; agreement "
          f"{both.sum() / (hit_ours | hit_drake).sum():.4f}; median depth difference "
          f"{1000 * np.median(np.abs(ours[both] - drake[both])):.2f} mm; "
          f"batched {per_image_us:.0f} us per image")


def main() -> None:
    """Loads the Panda, compares the renderers, tracks it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=2.0)
    parser.add_argument("--share", type=Path, help="example-robot-data's share folder",
                        default=Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix"
                        / "share" / "example-robot-data")
    args = parser.parse_args()
    if not args.share.is_dir():
        parser.error(f"example-robot-data's share folder {args.share} does not exist: "
                     f"pip install example-robot-data, or pass --share DIR")
    config = panda_config(args.share)
    print(yaml_dump_typed(config))
    render_agreement(config)

    model = build_tracker_model(config)
    home = default_home_positions(model.plant, model.robot_joint_names)
    robot = RobotMotion(config, dict(zip(model.robot_joint_names, home, strict=True)),
                        moved=PANDA_ARM, biased=PANDA_ARM)
    demo = build("32F", args.duration, seed=0, robot=robot, params=TrackerParams())
    times = np.arange(0.5, args.duration + 1e-9, 0.5)
    print_errors(times, hand_errors_mm(demo, times))


if __name__ == "__main__":
    main()
