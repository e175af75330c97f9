"""Builds and runs one closed-loop servo Diagram per pose feedback.

``build_servo_diagram(config, feedback)`` puts together the servo world
(``drake_tracker.servo.world``), the pose feedback (``drake_tracker.servo.feedback``:
``encoders``, ``tracker`` or ``truth``) and the controller
(``drake_tracker.servo.controller``); ``run_servo`` simulates it and samples the true
hand pose, the fed-back pose and the target index every ``sample_period_s``, with the
wall-clock time of the simulation (its real-time factor).

Everything random is seeded: the scenario's ``seed`` drives the encoders' noise and bias
and the camera's noise and clock; the tracker's ``TrackerParams.seed`` its particles.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder

from drake_tracker.kernel_warm_up import warm_up_tracker_kernels
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.progress import SimulatedSecondsBar
from drake_tracker.servo.config import FEEDBACK_LABELS, ServoStudyConfig
from drake_tracker.servo.controller import CameraFrameServo
from drake_tracker.servo.feedback import AddFeedback
from drake_tracker.servo.world import AddServoWorld, ServoWorld
from drake_tracker.sim.scenario.config import Scenario
from drake_tracker.sim.scenario.validation import require
from drake_tracker.systems.add_tracker import TrackerSystems

#: A hook that adds visualisation to a servo Diagram: (builder, world, feedback) -> None.
Visualize = Callable[[DiagramBuilder, ServoWorld, str], None]


def servo_scenario(config: ServoStudyConfig) -> Scenario:
    """The study's world: ``config.scenario`` loaded and checked, in dynamic mode (a world
    robot that differs from the model, ``model_mismatch``, is not supported)."""
    from drake_tracker.sim.scenario.load import load_scenario

    scenario = load_scenario(config.scenario)
    require(not scenario.model_mismatch.enabled, "scenario", config.scenario,
            "its model_mismatch is not supported by the servo study (the world simulates "
            "the nominal robot)")
    scenario.mode = "dynamic"
    return scenario


@dataclass
class ServoDiagram:
    """A built closed-loop Diagram and its parts."""

    diagram: Diagram
    world: ServoWorld
    controller: CameraFrameServo
    feedback: str
    #: The tracker's systems in run (b), else None.
    tracker: TrackerSystems | None


def build_servo_diagram(config: ServoStudyConfig, feedback: str,
                        scenario: Scenario | None = None, params: TrackerParams | None = None,
                        visualize: Visualize | None = None) -> ServoDiagram:
    """World + ``feedback`` (``encoders``, ``tracker`` or ``truth``) + controller.

    Only the tracker's run renders depth images (the other two need no camera), and only
    the pixels the tracker reads (``demo.render_what_the_tracker_reads``: the same
    images, at a fraction of the rendering cost)."""
    from drake_tracker.demo.run import render_what_the_tracker_reads

    scenario = scenario or servo_scenario(config)
    if feedback == "tracker":
        scenario = render_what_the_tracker_reads(scenario, params or TrackerParams())
    builder = DiagramBuilder()
    world = AddServoWorld(builder, scenario, config.gains.joint_servo_frequency_rad_per_s,
                          with_camera=feedback == "tracker")
    feed = AddFeedback(builder, world, feedback, params)
    controller = builder.AddNamedSystem("servo_controller", CameraFrameServo(
        world.robot_config, world.robot_joint_names, world.arm_joint_names, config))
    builder.Connect(feed.X_CE, controller.GetInputPort("X_CE"))
    builder.Connect(feed.joints, controller.GetInputPort("estimated_position"))
    if feed.usable is not None:
        builder.Connect(feed.usable, controller.GetInputPort("feedback_usable"))
    builder.Connect(world.ports["measured_position"],
                    controller.GetInputPort("measured_position"))
    builder.Connect(world.ports["measurement_time"],
                    controller.GetInputPort("measurement_time"))
    builder.Connect(controller.GetOutputPort("arm_command"), world.arm_command_input)
    if visualize is not None:
        visualize(builder, world, feedback)
    diagram = builder.Build()
    diagram.set_name(f"servo_{feedback}")
    return ServoDiagram(diagram, world, controller, feedback, feed.tracker)


@dataclass
class ServoRun:
    """One simulated closed-loop run, sampled every ``sample_period_s``."""

    feedback: str
    times_s: np.ndarray
    #: (T, 4, 4) the hand in the TRUE camera frame.
    true_X_CE: np.ndarray
    #: (T, 4, 4) the pose the controller was fed.
    feedback_X_CE: np.ndarray
    #: (T,) the target servoed to (-1 during the hold).
    target_index: np.ndarray
    wall_time_s: float
    #: (T,) whether the controller could act on its feed (the tracker's health).
    feedback_usable: np.ndarray | None = None

    @property
    def label(self) -> str:
        """The study's name of this run, e.g. ``(b) drake_tracker X_CE``."""
        return FEEDBACK_LABELS[self.feedback]

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return float(self.times_s[-1]) / self.wall_time_s if self.wall_time_s > 0 else np.inf


def run_servo(config: ServoStudyConfig, feedback: str, scenario: Scenario | None = None,
              params: TrackerParams | None = None, duration_s: float | None = None,
              visualize: Visualize | None = None, progress: bool = True) -> ServoRun:
    """Builds the ``feedback`` run's Diagram, simulates it for ``duration_s`` (default:
    ``config.duration_s``) and returns the sampled run."""
    built = build_servo_diagram(config, feedback, scenario, params, visualize)
    if built.tracker is not None:  # compile or load its kernels before the clock starts
        processor = built.tracker.image_update.processor
        seconds = warm_up_tracker_kernels(built.tracker.model, processor.update.camera,
                                          processor.params)
        if progress:
            print(f"the tracker's kernels loaded in {seconds:.1f} s (a machine's first run "
                  f"compiles them)", flush=True)
    duration = config.duration_s if duration_s is None else float(duration_s)
    simulator = Simulator(built.diagram)
    root = simulator.get_mutable_context()
    built.world.set_initial_state(root)
    ports = (built.world.ports["true_X_CE"], built.controller.GetInputPort("X_CE"),
             built.controller.GetOutputPort("target_index"))
    contexts = [p.get_system().GetMyContextFromRoot(root) for p in ports]
    dt = config.sample_period_s
    times = np.arange(0.0, duration + 0.5 * dt, dt)
    usable_port = built.controller.GetInputPort("feedback_usable")
    true_X, fed_X, index, usable = [], [], [], []
    wall_start = time.perf_counter()
    simulator.Initialize()
    with SimulatedSecondsBar(duration, f"servo {feedback}", enabled=progress) as bar:
        for t in times:
            simulator.AdvanceTo(float(t))
            bar.advance_to(t)
            true_X.append(ports[0].Eval(contexts[0]).GetAsMatrix4())
            fed_X.append(ports[1].Eval(contexts[1]).GetAsMatrix4())
            index.append(int(ports[2].Eval(contexts[2])[0]))
            usable.append(not usable_port.HasValue(contexts[1])
                          or usable_port.Eval(contexts[1])[0] > 0.5)
    wall = time.perf_counter() - wall_start
    return ServoRun(feedback, times, np.array(true_X), np.array(fed_X), np.array(index), wall,
                    np.array(usable))
