"""The static scene around the robot: a floor, a table and a back wall."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant


def add_environment(plant: MultibodyPlant) -> None:
    """A floor (z = 0), a table and a back wall, visual (illustration and perception)
    geometry on the world body, in front of (+x of) the robot's base."""
    world = plant.world_body()
    items = (
        ("floor", (6.0, 6.0, 0.02), (1.0, 0.0, -0.01), (0.55, 0.5, 0.45, 1.0)),
        ("table", (0.8, 1.4, 0.04), (1.05, 0.0, 0.35), (0.45, 0.3, 0.2, 1.0)),
        ("back_wall", (0.05, 6.0, 3.0), (2.6, 0.0, 1.5), (0.8, 0.8, 0.75, 1.0)),
    )
    for name, size, xyz, rgba in items:
        plant.RegisterVisualGeometry(world, RigidTransform(np.array(xyz)), Box(*size),
                                     f"environment_{name}", np.array(rgba))
