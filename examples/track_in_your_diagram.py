"""Adding drake_tracker to your own Diagram, next to a simulated robot.

Run: python examples/track_in_your_diagram.py [--duration 2.0]

What the tracker needs from your Diagram:
  * the robot's model (a URDF/SDF with a camera frame and an end-effector frame), given
    as a ``RobotConfig``; ``build_tracker_model`` adds the six virtual camera joints;
  * a vector port of the encoder readings in ``model.robot_joint_names`` order, and a
    1-vector port with their time stamp;
  * an abstract port of ``DepthFrame`` (depth image in metres with its capture time);
  * the camera's intrinsics and the encoder period.
Here the simulated world (``AddSimulatedWorld``) provides all of them.
"""

import argparse

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.params import TrackerParams
from drake_tracker.sim.scenario import load_scenario
from drake_tracker.sim.world import AddSimulatedWorld
from drake_tracker.systems.add_tracker import AddTracker


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=2.0)
    args = parser.parse_args()

    builder = DiagramBuilder()
    world = AddSimulatedWorld(builder, load_scenario("s-full-arm/constant"))
    params = TrackerParams()  # or load_tracker_params("my_params.yaml")
    tracker = AddTracker(builder, world.model, world.intrinsics, params,
                         measured_position=world.port("measured_position"),
                         measurement_time=world.port("measurement_time"),
                         depth_frame=world.port("depth_frame"),
                         encoder_period_s=world.encoder_period_s)
    diagram = builder.Build()

    simulator = Simulator(diagram)
    simulator.AdvanceTo(args.duration)
    context = simulator.get_context()

    def value(port):
        return port.Eval(port.get_system().GetMyContextFromRoot(context))

    X_CE = value(tracker.port("X_CE")).GetAsMatrix4()
    X_CE_true = value(world.port("true_X_CE")).GetAsMatrix4()
    print("estimated camera offset [m, m, m, rad, rad, rad]:",
          np.round(value(tracker.port("camera_offset")), 4))
    print("true camera offset:", np.round(value(world.port("true_camera_offset")), 4))
    print("estimated arm biases (deg):",
          np.round(np.degrees(value(tracker.port("bias"))[:7]), 2))
    print("hand position error (mm):",
          round(1000 * float(np.linalg.norm(X_CE[:3, 3] - X_CE_true[:3, 3])), 1))


if __name__ == "__main__":
    main()
