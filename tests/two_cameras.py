"""Apollo with a second depth camera on a post, and the camera model of both (shared by
the tests of several cameras: ``systems/``, ``robustness/test_camera_remount.py``,
``io/test_estimates_bag.py``), a recorded two-camera run in a folder (``io/``'s bag
and LCM tests), and the calibration tests' recording (``calibration/``)."""

import numpy as np

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import CameraMount, FrameOffset, robot_preset

CAMERA = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
POST = FrameOffset(parent="torso", xyz_m=[1.2, -1.45, 1.45], rpy_deg=[-114.44, 0.0, 38.29])


def two_camera_config():
    config = robot_preset("apollo")
    config.added_frames = {"post_nominal": POST}
    config.cameras = [CameraMount("camera", "camera_optical"),
                      CameraMount("post", "post_nominal")]
    return config


def recorded_two_cameras(folder, ticks_per_second: int):
    """1.5 s of occlusion-lasting-2cam/constant, its stamps rounded to ``ticks_per_second``,
    written to ``folder`` as ``run.npz``, ``robot.yaml`` (its robot) and ``params.yaml``
    (the tests' small parameters); returns the run."""
    from fast_params import small_params

    from drake_tracker.params.loading import tracker_params_to_yaml
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario

    run = simulate_and_record(load_scenario("occlusion-lasting-2cam/constant"),
                              duration_s=1.5).stamped_in(ticks_per_second)
    run.save(folder / "run.npz")
    (folder / "robot.yaml").write_text(run.robot_config_yaml)
    (folder / "params.yaml").write_text(tracker_params_to_yaml(small_params()))
    return run


def in_out_in_recording(duration_s: float):
    """``duration_s`` of in-out-in-2cam/none, world seed 7: both cameras see the arm,
    each mounted off its nominal pose (the preset's 31 mm / 3.2 deg and 27 mm / 2.7 deg;
    the calibration tests)."""
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario

    scenario = load_scenario("in-out-in-2cam/none")
    scenario.seed = 7
    return simulate_and_record(scenario, duration_s=duration_s)
