"""Adding drake_tracker to a plain Drake Diagram: a MultibodyPlant, a stock RgbdSensor.

Run: python examples/track_in_your_diagram.py [--duration 4] [--depth 32F|16U]

The Diagram is what a Drake user already has: the robot's MultibodyPlant (Apollo,
shipped in ``models/``; ``examples/vendor_robot.py`` runs the same with a vendor's
Franka Panda), posed along a trajectory by a ``TrajectorySource``; a stock
``RgbdSensor`` at the robot's camera frame, mounted 2 cm / 2 deg off its nominal pose;
and encoders. The only custom part is the encoder bias
(:class:`drake_tracker.sim.encoders.BiasedEncoders`: 8.6 deg on every arm joint).

What the tracker takes from it:
  * the robot's model as a ``RobotConfig`` (its camera and end-effector frames);
  * the encoder readings (a vector port, ``model.robot_joint_names`` order) and their
    time stamp (a 1-vector port);
  * the sensor's ``depth_image_32f`` (m) or ``depth_image_16u`` (mm) and the images'
    capture time: an ``ImageStamper`` samples the sensor at 30 Hz and holds the image
    with its time (``RgbdSensorAsync`` has both ports itself);
  * the sensor's camera model (``default_depth_render_camera()``, or a ``CameraInfo``).
"""

import argparse
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    Box,
    ClippingRange,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
    SceneGraph,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.systems.rendering import MultibodyPositionToGeometryPose
from pydrake.systems.sensors import CameraInfo, RgbdSensor
from pydrake.trajectories import PiecewisePolynomial

from drake_tracker import (
    AddImageStamper,
    AddTracker,
    RobotConfig,
    TrackerParams,
    TrackerSystems,
    build_tracker_model,
)
from drake_tracker.robot.model import add_robot
from drake_tracker.sim.encoders import BiasedEncoders
from drake_tracker.sim.scenario.load import EncoderConfig


@dataclass
class RobotMotion:
    """A robot and how the example moves it: ``moved`` joints swing 15 deg about
    ``home_rad`` (joints not listed there stay at 0), ``biased`` ones read 8.6 deg off."""

    config: RobotConfig
    home_rad: dict[str, float]
    moved: list[str]
    biased: list[str]


ARM = [f"arm_joint_{k}" for k in range(1, 8)]
#: Apollo, with the hand in the head camera's view.
APOLLO = RobotMotion(
    RobotConfig("apollo.sdf", camera_frame="camera_optical", end_effector_frame="end_effector"),
    home_rad={name: np.radians(deg) for name, deg in (
        ("head_tilt", 32.0), ("arm_joint_1", 20.0), ("arm_joint_2", 60.0),
        ("arm_joint_4", -60.0), ("arm_joint_6", -30.0))},
    moved=ARM, biased=ARM)
#: The camera's true mounting relative to its nominal frame: 2 cm and 2 deg off.
X_NOMINAL_TRUE = RigidTransform(RollPitchYaw(np.radians([2.0, -1.5, 1.0])),
                                np.array([0.02, -0.015, 0.01]))


@dataclass
class TrackingDemo:
    """The built Diagram and what is needed to read the truth back."""

    diagram: Diagram
    tracker: TrackerSystems
    plant: MultibodyPlant
    trajectory: PiecewisePolynomial
    encoders: BiasedEncoders
    config: RobotConfig

    def true_X_CE(self, t: float) -> np.ndarray:
        """The hand in the TRUE camera frame at time ``t`` (4x4)."""
        context = self.plant.CreateDefaultContext()
        self.plant.SetPositions(context, self.trajectory.value(t).ravel())
        X_WN = self.plant.GetFrameByName(self.config.camera_frame).CalcPoseInWorld(context)
        X_WE = self.plant.GetFrameByName(self.config.end_effector_frame).CalcPoseInWorld(
            context)
        return ((X_WN @ X_NOMINAL_TRUE).inverse() @ X_WE).GetAsMatrix4()

    def encoders_only_X_CE(self, readings: np.ndarray) -> np.ndarray:
        """The hand in the NOMINAL camera frame at the encoder ``readings`` (4x4)."""
        context = self.plant.CreateDefaultContext()
        self.plant.SetPositions(context, readings)
        return self.plant.CalcRelativeTransform(
            context, self.plant.GetFrameByName(self.config.camera_frame),
            self.plant.GetFrameByName(self.config.end_effector_frame)).GetAsMatrix4()


def sinusoid(plant: MultibodyPlant, robot: RobotMotion, duration_s: float
             ) -> PiecewisePolynomial:
    """The moved joints swing 15 deg about the home pose, each with its own period."""
    home = np.zeros(plant.num_positions())
    for name, angle in robot.home_rad.items():
        home[plant.GetJointByName(name).position_start()] = angle
    times = np.arange(0.0, duration_s + 0.02, 0.01)
    q = np.tile(home[:, None], (1, len(times)))
    for k, name in enumerate(robot.moved):
        row = plant.GetJointByName(name).position_start()
        q[row] += np.radians(15.0) * np.sin(2 * np.pi * times / (8.0 * (1 + 0.17 * k)))
    return PiecewisePolynomial.CubicShapePreserving(times, q)


def build(depth: str = "32F", duration_s: float = 4.0, seed: int = 0,
          robot: RobotMotion = APOLLO, params: TrackerParams | None = None) -> TrackingDemo:
    """The Diagram: plant, RgbdSensor (``depth`` 32F or 16U), encoders, tracker."""
    builder = DiagramBuilder()
    scene_graph = builder.AddSystem(SceneGraph())
    scene_graph.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams()))
    plant = MultibodyPlant(time_step=0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    # Your own Parser code works as well; add_robot also adds the config's frames.
    add_robot(plant, robot.config)
    for name, size, xyz in (("floor", (6, 6, 0.02), (1, 0, -0.01)),
                            ("table", (0.8, 1.4, 0.04), (1.05, 0, 0.35))):
        plant.RegisterVisualGeometry(plant.world_body(), RigidTransform(np.array(xyz)),
                                     Box(*size), name, np.array([0.5, 0.45, 0.4, 1.0]))
    plant.Finalize()

    # The robot moves along a trajectory; SceneGraph places its geometry there.
    trajectory = sinusoid(plant, robot, duration_s)
    motion = builder.AddSystem(TrajectorySource(trajectory))
    to_pose = builder.AddSystem(MultibodyPositionToGeometryPose(plant))
    builder.Connect(motion.get_output_port(), to_pose.get_input_port())
    builder.Connect(to_pose.get_output_port(),
                    scene_graph.get_source_pose_port(plant.get_source_id()))

    # A stock RgbdSensor on the head, sampled at 30 Hz with its capture time.
    nominal = plant.GetFrameByName(robot.config.camera_frame)
    camera = DepthRenderCamera(
        RenderCameraCore("vtk", CameraInfo(320, 240, np.radians(45.0)),
                         ClippingRange(0.1, 6.0), RigidTransform()),
        DepthRange(0.1, 6.0))
    sensor = builder.AddSystem(RgbdSensor(
        plant.GetBodyFrameIdOrThrow(nominal.body().index()),
        nominal.GetFixedPoseInBodyFrame() @ X_NOMINAL_TRUE, camera))
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    image_port = {"32F": sensor.depth_image_32F_output_port(),
                  "16U": sensor.depth_image_16U_output_port()}[depth]
    stamper = AddImageStamper(builder, image_port, period_s=1.0 / 30.0)

    # Encoders at 1 kHz with a constant 8.6 deg bias on the arm joints.
    model = build_tracker_model(robot.config)
    config = EncoderConfig(rate_hz=1000.0, bias="constant", constant_bias_deg=8.6)
    encoders = builder.AddSystem(BiasedEncoders(model.robot_joint_names, config, seed,
                                                 robot.biased))
    builder.Connect(motion.get_output_port(), encoders.get_input_port(0))

    tracker = AddTracker(builder, model=model, camera=sensor.default_depth_render_camera(),
                         params=params or TrackerParams(),
                         measured_position=encoders.GetOutputPort("measured_position"),
                         measurement_time=encoders.GetOutputPort("measurement_time"),
                         depth=stamper.GetOutputPort("image"),
                         image_time=stamper.GetOutputPort("image_time"),
                         encoder_period_s=1.0 / config.rate_hz)
    return TrackingDemo(builder.Build(), tracker, plant, trajectory, encoders, robot.config)


def hand_errors_mm(demo: TrackingDemo, times_s: np.ndarray) -> dict[str, np.ndarray]:
    """Simulates to each of ``times_s`` and returns the hand position error (mm) of the
    tracker and of the encoders alone against the truth."""
    simulator = Simulator(demo.diagram)
    context = simulator.get_context()
    errors: dict[str, list[float]] = {"tracker": [], "encoders_only": []}
    for t in times_s:
        simulator.AdvanceTo(float(t))
        X_CE = demo.tracker.X_CE.Eval(
            demo.tracker.kalman_bank.GetMyContextFromRoot(context)).GetAsMatrix4()
        readings = demo.encoders.GetOutputPort("measured_position").Eval(
            demo.encoders.GetMyContextFromRoot(context))
        truth = demo.true_X_CE(t)
        for key, estimate in (("tracker", X_CE),
                              ("encoders_only", demo.encoders_only_X_CE(readings))):
            errors[key].append(1000 * np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))
    return {key: np.array(value) for key, value in errors.items()}


def print_errors(times_s: np.ndarray, errors: dict[str, np.ndarray]) -> None:
    """Prints ``hand_errors_mm``'s result as a table."""
    print("time (s)  tracker (mm)  encoders only (mm)")
    for t, a, b in zip(times_s, errors["tracker"], errors["encoders_only"], strict=True):
        print(f"{t:8.1f}  {a:12.1f}  {b:18.1f}")


def main() -> None:
    """Builds the Diagram, simulates it, and prints the hand position errors."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=4.0)
    parser.add_argument("--depth", choices=("32F", "16U"), default="32F")
    args = parser.parse_args()
    demo = build(args.depth, args.duration)
    times = np.arange(0.5, args.duration + 1e-9, 0.5)
    print_errors(times, hand_errors_mm(demo, times))


if __name__ == "__main__":
    main()
