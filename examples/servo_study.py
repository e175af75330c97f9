"""Closed-loop study: servo the hand to targets seen by the camera, with and without the
tracker. The same study as ``drake-tracker servo``, written out with the building blocks.

Run: python examples/servo_study.py [--duration 13] [--scenario static/time-varying]
     [--out out/servo_example]

The Diagram, once per feedback (a, b, c), is

    world (dynamic plant + joint servo + biased encoders [+ depth camera])
      -> feedback (X_CE and joint angles):
                        (a) forward kinematics of the encoders, nominal camera
                        (b) drake_tracker's AddTracker(...): X_CE, estimated_position,
                            health (the controller holds the arm while it is LOST)
                        (c) the truth
      -> CameraFrameServo (Cartesian law in the camera frame + Drake's differential IK)
      -> the joint servo's command (InverseDynamicsController)

Swap ``CameraFrameServo`` for your own controller: it needs an ``X_CE`` input (the hand
in the camera frame), joint angles and the encoders, and outputs [valid, q, v] of the arm
joints.
"""

import argparse
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import MatrixGain

from drake_tracker.demo.run import render_what_the_tracker_reads
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.servo.config import FEEDBACK_LABELS, FEEDBACKS, ServoStudyConfig
from drake_tracker.servo.controller import CameraFrameServo
from drake_tracker.servo.feedback import EncoderKinematicsPose, HealthToUsable
from drake_tracker.servo.outcomes import format_outcome_table, target_outcomes
from drake_tracker.servo.report import plot_servo_errors
from drake_tracker.servo.study import ServoRun, servo_scenario
from drake_tracker.servo.world import AddServoWorld, camera_model
from drake_tracker.systems.add_tracker import AddTracker


def build(config: ServoStudyConfig, feedback: str, scenario, params: TrackerParams):
    """The closed-loop Diagram of one run; returns (diagram, world, controller)."""
    builder = DiagramBuilder()
    # Only the tracker needs the depth camera (the other runs skip rendering), and only
    # the pixels it reads (the same images, rendered at a fraction of the cost).
    if feedback == "tracker":
        scenario = render_what_the_tracker_reads(scenario, params)
    world = AddServoWorld(builder, scenario, config.gains.joint_servo_frequency_rad_per_s,
                          with_camera=feedback == "tracker")
    if feedback == "encoders":  # (a) what the robot knows without the tracker
        fk = builder.AddSystem(EncoderKinematicsPose(world.robot_config,
                                                     world.robot_joint_names))
        builder.Connect(world.ports["measured_position"], fk.get_input_port(0))
        X_CE, joints = fk.GetOutputPort("X_CE"), world.ports["measured_position"]
    elif feedback == "tracker":  # (b) drake_tracker next to the plant and the camera
        tracker = AddTracker(builder, model=world.model, camera=camera_model(scenario),
                             params=params, measured_position=world.ports["measured_position"],
                             measurement_time=world.ports["measurement_time"],
                             depth=world.ports["depth_frame"],
                             encoder_period_s=world.encoder_period_s)
        X_CE = tracker.X_CE
        # Its joint estimate covers the six virtual camera joints too: keep the robot's.
        select = np.array([[1.0 if name == robot_name else 0.0
                            for name in world.model.joint_names]
                           for robot_name in world.robot_joint_names])
        robot_joints = builder.AddSystem(MatrixGain(select))
        builder.Connect(tracker.estimated_position, robot_joints.get_input_port())
        joints = robot_joints.get_output_port()
        # The tracker's health: the controller holds the arm while it is LOST.
        usable = builder.AddSystem(HealthToUsable())
        builder.Connect(tracker.health, usable.get_input_port(0))
    else:  # (c) the ideal
        X_CE, joints = world.ports["true_X_CE"], world.ports["true_position"]
    controller = builder.AddSystem(CameraFrameServo(
        world.robot_config, world.robot_joint_names, world.arm_joint_names, config))
    builder.Connect(X_CE, controller.GetInputPort("X_CE"))
    builder.Connect(joints, controller.GetInputPort("estimated_position"))
    builder.Connect(world.ports["measured_position"],
                    controller.GetInputPort("measured_position"))
    builder.Connect(world.ports["measurement_time"],
                    controller.GetInputPort("measurement_time"))
    if feedback == "tracker":
        builder.Connect(usable.get_output_port(0), controller.GetInputPort("feedback_usable"))
    builder.Connect(controller.GetOutputPort("arm_command"), world.arm_command_input)
    return builder.Build(), world, controller


def simulate(config: ServoStudyConfig, feedback: str, scenario, params: TrackerParams,
             duration_s: float) -> ServoRun:
    """Simulates one run and samples the true hand pose every ``sample_period_s``."""
    import time

    diagram, world, controller = build(config, feedback, scenario, params)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    world.set_initial_state(context)
    truth_context = world.truth.GetMyContextFromRoot(context)
    controller_context = controller.GetMyContextFromRoot(context)
    times = np.arange(0.0, duration_s + 1e-9, config.sample_period_s)
    true_X, fed_X, index = [], [], []
    start = time.perf_counter()
    for t in times:
        simulator.AdvanceTo(float(t))
        true_X.append(world.ports["true_X_CE"].Eval(truth_context).GetAsMatrix4())
        fed_X.append(controller.GetInputPort("X_CE").Eval(controller_context).GetAsMatrix4())
        index.append(config.target_index(float(t)))
    return ServoRun(feedback, times, np.array(true_X), np.array(fed_X), np.array(index),
                    time.perf_counter() - start)


def main() -> None:
    """Runs (a), (b), (c) and prints each target's final error; writes the plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=None)
    parser.add_argument("--scenario", default="static/constant")
    parser.add_argument("--out", default="out/servo_example")
    args = parser.parse_args()
    config = ServoStudyConfig(scenario=args.scenario)
    scenario = servo_scenario(config)
    duration = config.duration_s if args.duration is None else args.duration
    runs = {}
    for feedback in FEEDBACKS:
        runs[feedback] = simulate(config, feedback, scenario, TrackerParams(), duration)
        print(f"{FEEDBACK_LABELS[feedback]}: real-time factor "
              f"{runs[feedback].real_time_factor:.2f}", flush=True)
    outcomes = {f: target_outcomes(run, config) for f, run in runs.items()}
    print(format_outcome_table(outcomes, FEEDBACK_LABELS, 1000 * config.settle_threshold_m))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plot_servo_errors(runs, config, out / "servo_errors.png", f"{scenario.name} (example)")
    print(f"wrote {out / 'servo_errors.png'}")


if __name__ == "__main__":
    main()
