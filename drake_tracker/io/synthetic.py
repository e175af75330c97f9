"""Small synthetic recorded runs rendered from the tracker's own model, without the
simulated world: for unit tests and benchmarks of the tracker core.

The images are the robot rendered by Drake's RenderEngineVtk (``renderer="drake"``, the
independent reference) or by the batched renderer, at the TRUE configuration (robot
joints and camera offset), in front of a flat background at ``background_m``, with
Gaussian depth noise. Readings are the true angles plus a constant bias and noise.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.yaml import yaml_dump

from drake_tracker.core.filter.estimate import PoseReadout
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.configurations import default_view_configuration
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.io.recording import RecordedRun

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel


def synthetic_run(model: TrackerModel, duration_s: float = 1.0, encoder_rate_hz: float = 200.0,
                  image_rate_hz: float = 30.0, delay_s: float = 0.05,
                  camera: CameraIntrinsics | None = None, bias_rad: float = np.radians(3.0),
                  camera_offset: np.ndarray | None = None, amplitude_rad: float = 0.1,
                  period_s: float = 4.0, depth_noise_m: float = 0.002,
                  background_m: float = 2.5, renderer: str = "batched",
                  biased_joints: list[str] | None = None, seed: int = 0,
                  bias_step_rad: float = 0.0, bias_step_time_s: float = np.inf) -> RecordedRun:
    """A RecordedRun of the robot moving sinusoidally around its default view pose.

    Every robot joint (or those in ``biased_joints``) gets ``bias_rad`` of encoder bias,
    which steps by ``bias_step_rad`` at ``bias_step_time_s``;
    ``camera_offset`` (6) is the true camera pose relative to the nominal one (default:
    1 cm, 1 deg on each axis); with several cameras in ``model``, the first camera's (its
    images are the run's), the others' offsets 0.
    """
    rng = np.random.default_rng(seed)
    camera = camera or CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
    offset = (np.array([0.01, -0.01, 0.01, 0.017, -0.017, 0.017]) if camera_offset is None
              else np.asarray(camera_offset, float))
    robot = model.robot_joint_indices
    home = default_view_configuration(model)
    phases = np.linspace(0.0, np.pi, len(robot))

    def truth(t: np.ndarray) -> np.ndarray:
        q = np.tile(home, (len(t), 1))
        q[:, robot] += amplitude_rad * np.sin(2 * np.pi * t[:, None] / period_s + phases)
        q[:, model.camera_joint_indices(model.camera_names[0])] = offset  # the others: 0
        return q

    reading_times = np.arange(0.0, duration_s, 1.0 / encoder_rate_hz)
    q_read = truth(reading_times)[:, robot]
    names = list(model.robot_joint_names)
    biased = np.array([n in (biased_joints or names) for n in names], float)
    def bias(t: np.ndarray) -> np.ndarray:
        return (bias_rad + bias_step_rad * (t >= bias_step_time_s))[:, None] * biased

    readings = q_read + bias(reading_times) + rng.normal(0.0, 1e-4, q_read.shape)
    capture = np.arange(0.0, duration_s - delay_s, 1.0 / image_rate_hz)
    images = make_renderer(model, camera, renderer).render(truth(capture))
    images = np.where(np.isfinite(images), images, background_m)
    images = images + rng.normal(0.0, depth_noise_m, images.shape)
    truth_times = reading_times[::max(1, int(round(encoder_rate_hz / 100.0)))]
    q_truth = truth(truth_times)
    X_CE = PoseReadout(model).poses(q_truth)[0]
    return RecordedRun(
        robot_config_yaml=yaml_dump({"model_file": model.config.model_file,
                                     "camera_frame": model.config.camera_frame,
                                     "end_effector_frame": model.config.end_effector_frame}),
        joint_names=list(model.robot_joint_names),
        reading_times_s=reading_times,
        readings_rad=readings,
        image_capture_times_s=capture,
        image_arrival_times_s=capture + delay_s,
        depth_images_m=images.astype(np.float32),
        camera_intrinsics=camera,
        truth_times_s=truth_times,
        truth_positions_rad=q_truth[:, robot],
        truth_bias_rad=bias(truth_times),
        truth_camera_offset=np.tile(offset, (len(truth_times), 1)),
        truth_X_CE=X_CE,
    )
