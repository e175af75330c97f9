"""One Meshcat scene (and recording) of the three servo runs, with the targets as triads.

The three runs are simulated one after the other on the same Meshcat; each draws its
robot under its own path, on the same time axis, so the recording replays them side by
side: (b), the tracker in the loop, as the full world (robot in its own colours, table,
wall); (a) as a translucent blue robot and (c) as a translucent grey one. The targets are
triads (x red, y green, z blue) at their poses in the world, placed from the TRUE camera
(the head holds still, so they do not move).
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import (
    Cylinder,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.framework import DiagramBuilder

from drake_tracker.demo.meshcat_views import ENCODERS_RGBA, AddGhostRobot, LegendEntry
from drake_tracker.servo.config import FEEDBACK_LABELS, ServoStudyConfig
from drake_tracker.servo.world import ServoWorld

#: Colours of the runs drawn as ghosts.
RUN_RGBA = {"encoders": ENCODERS_RGBA, "truth": Rgba(0.35, 0.35, 0.35, 0.35)}
#: Meshcat paths of the runs.
RUN_PATHS = {"encoders": "servo_a_encoders", "tracker": "servo_b_tracker",
             "truth": "servo_c_truth"}
FRAMES_PER_SECOND = 30.0


class ServoMeshcatView:
    """Adds each run's drawing to its Diagram (``visualize``) and the target triads."""

    def __init__(self, meshcat: Meshcat, config: ServoStudyConfig):
        self.meshcat = meshcat
        self._config = config
        self._targets_drawn = False

    def start_recording(self) -> None:
        """Records every run from now on (call before the first run)."""
        self.meshcat.StartRecording(frames_per_second=FRAMES_PER_SECOND)

    def visualize(self, builder: DiagramBuilder, world: ServoWorld, feedback: str) -> None:
        """The ``Visualize`` hook of ``drake_tracker.servo.study.run_servo``."""
        period = 1.0 / FRAMES_PER_SECOND
        path = RUN_PATHS[feedback]
        if feedback in RUN_RGBA:
            AddGhostRobot(builder, world.robot_config, self.meshcat,
                          world.ports["plant_positions"], path, RUN_RGBA[feedback])
        else:
            MeshcatVisualizer.AddToBuilder(
                builder, world.scene_graph, self.meshcat,
                MeshcatVisualizerParams(role=Role.kIllustration, prefix=path,
                                        publish_period=period))
        if not self._targets_drawn:
            self._draw_targets(world)
            self._targets_drawn = True

    def _draw_targets(self, world: ServoWorld) -> None:
        context = world.plant.CreateDefaultContext()  # the home pose, true camera offset
        X_WC = world.camera_frame.CalcPoseInWorld(context)
        for k, target in enumerate(self._config.targets):
            add_triad(self.meshcat, f"targets/target_{k + 1}", X_WC @ target.X_CT())
        center = X_WC @ self._config.targets[0].X_CT()
        p = center.translation()
        self.meshcat.SetCameraPose(p + [1.2, -0.9, 0.6], p)

    def finish(self) -> str:
        """Stops and publishes the recording; the standalone HTML with a legend."""
        from drake_tracker.demo.meshcat_views import add_legend

        self.meshcat.StopRecording()
        self.meshcat.PublishRecording()
        return add_legend(self.meshcat.StaticHtml(), legend_entries())


def add_triad(meshcat: Meshcat, path: str, X_WT: RigidTransform, length_m: float = 0.06,
              radius_m: float = 0.003) -> None:
    """Three cylinders along the x (red), y (green) and z (blue) axes of ``X_WT``."""
    axes = ((RollPitchYaw(0, np.pi / 2, 0), [1, 0, 0], Rgba(1, 0, 0, 1)),
            (RollPitchYaw(-np.pi / 2, 0, 0), [0, 1, 0], Rgba(0, 0.8, 0, 1)),
            (RollPitchYaw(0, 0, 0), [0, 0, 1], Rgba(0, 0, 1, 1)))
    meshcat.SetTransform(path, X_WT)
    for name, (rpy, axis, rgba) in zip("xyz", axes, strict=True):
        meshcat.SetObject(f"{path}/{name}", Cylinder(radius_m, length_m), rgba)
        meshcat.SetTransform(f"{path}/{name}",
                             RigidTransform(rpy, 0.5 * length_m * np.array(axis, float)))


def legend_entries() -> list[LegendEntry]:
    """The legend of the servo scene."""
    return [LegendEntry(None, f"<b>{FEEDBACK_LABELS['tracker']}</b>: the robot in its "
                              "own colours"),
            LegendEntry(RUN_RGBA["encoders"], f"<b>{FEEDBACK_LABELS['encoders']}</b>"),
            LegendEntry(RUN_RGBA["truth"], f"<b>{FEEDBACK_LABELS['truth']}</b>"),
            LegendEntry(None, "triads: the targets (x red, y green, z blue), 1 to 4")]
