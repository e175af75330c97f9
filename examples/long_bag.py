"""Writes a long ROS 2 MCAP bag of full-size depth images, to show that ``track --bag``
streams it in flat memory (issue 44).

The bag holds ``--minutes`` of 640 x 480 16UC1 depth at 30 Hz and joint states at 100
Hz: the frames of a short simulated run, upsampled 8x and played in a loop (a 10-minute
bag is about 11 GB). Then, for example::

    python examples/long_bag.py --minutes 10 --out /tmp/long.mcap
    /usr/bin/time -v drake-tracker track --bag /tmp/long.mcap --robot /tmp/long.yaml \\
        --params examples/params.yaml --out /tmp/long_tracked

and compare "Maximum resident set size" with a 1-minute bag's.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from drake_tracker.io.ros_messages import RosMessages, bag_writer
from drake_tracker.io.run_bag import DEFAULT_BASE_NS
from drake_tracker.sim.record import simulate_and_record
from drake_tracker.sim.scenario.load import load_scenario

UPSAMPLE = 8


def main() -> None:
    """Simulates 2 s, then writes the looped bag and the robot's YAML beside it."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--out", required=True, help="the .mcap to write")
    args = parser.parse_args()
    out = Path(args.out)
    run = simulate_and_record(load_scenario("s-full-arm/constant"), duration_s=2.0)
    out.with_suffix(".yaml").write_text(run.robot_config_yaml)
    cam = run.camera_intrinsics
    frames = [np.round(np.nan_to_num(np.kron(d, np.ones((UPSAMPLE, UPSAMPLE))), nan=0.0)
                       * 1e3).astype(np.uint16) for d in run.depth_images_m]
    m = RosMessages()
    writer = bag_writer(out)
    joints = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState",
                                   typestore=m.store)
    depth = writer.add_connection("/camera/depth/image_raw", "sensor_msgs/msg/Image",
                                  typestore=m.store)
    info = writer.add_connection("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo",
                                 typestore=m.store)
    duration_ns = int(args.minutes * 60e9)
    reading_ns, image_ns = 10_000_000, 33_333_333
    t_reading, t_image, k = 0, 5_000_000, 0
    while t_reading < duration_ns:
        if t_image < t_reading:
            stamp = DEFAULT_BASE_NS + t_image
            frame = frames[k % len(frames)]
            writer.write(info, stamp, m.serialize(m.camera_info(
                stamp, "camera", cam.width * UPSAMPLE, cam.height * UPSAMPLE,
                cam.fx * UPSAMPLE, cam.fy * UPSAMPLE, (cam.cx + 0.5) * UPSAMPLE - 0.5,
                (cam.cy + 0.5) * UPSAMPLE - 0.5)))
            writer.write(depth, stamp, m.serialize(m.depth_image(stamp, "camera", frame)))
            t_image += image_ns
            k += 1
        stamp = DEFAULT_BASE_NS + t_reading
        i = (t_reading // 1_000_000) % len(run.reading_times_s)
        writer.write(joints, stamp, m.serialize(m.joint_state(
            stamp, run.joint_names, run.readings_rad[i])))
        t_reading += reading_ns
    writer.close()
    print(f"wrote {out}: {k} images of {cam.width * UPSAMPLE}x{cam.height * UPSAMPLE}, "
          f"{out.stat().st_size / 1e9:.1f} GB; robot: {out.with_suffix('.yaml')}")


if __name__ == "__main__":
    main()
