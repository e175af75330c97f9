"""A level of detail chosen body by body, by measuring it against the full meshes.

One clustering cell for the whole robot (:func:`~drake_tracker.core.render.level_of_detail.
level_of_detail`) is too coarse for a vendor's thin, rounded links and finer than a
bulky link needs: example-robot-data's Panda, seen from 1.5 m at 80x60, agreed with
Drake's RenderEngineVtk on only 98.6 % of its robot pixels at the 3 px cell, while its
fingers cost 26 triangles each. And most of a CAD robot's meshes are not closed (small
cracks and seams; 80 % of the Panda's triangles), so they lost back-face culling,
which halves the rasteriser's cost per triangle.

So each body gets the cheapest of its options that keeps the robot's image what the
full meshes give, measured on depth images of calibration configurations:

* its options are its own meshes and their clusterings on a ladder of cells (those that
  divide its triangle count by ``min_reduction``), each with back-face culling where it
  is exact (a closed mesh) and, for an open one, also with culling imposed;
* each option's error is counted on the body rendered alone, against the body's full
  meshes rendered alone (a pixel is wrong if its robot/background label differs, or its
  depth by more than ``depth_tolerance_m``), on the pixels no other body covers (where
  another body is, the robot's label cannot change): errors of different bodies then add
  up to the robot's, but where two bodies err on one pixel;
* starting from every body's cheapest option, the option that removes the most wrong
  pixels per unit of cost (:attr:`BodyOption.cost`: triangles and vertices) is taken
  until the wrong pixels are at most ``max_disagreement`` of the robot's, and each body
  then takes the cheapest option that keeps them so; the chosen meshes are rendered
  together and measured, and chosen again for a smaller sum while that measurement is
  above the budget.

A culled option's error includes what culling shows through the mesh's cracks, so
culling an open mesh is chosen only where the calibration images cannot tell.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drake_tracker.core.render.level_of_detail import (
    BodyMesh,
    cluster_body,
    join_bodies,
    split_bodies,
)
from drake_tracker.core.render.meshes import RobotMeshes

#: The costs of an option, per culled triangle: an unculled triangle (half of a culled
#: mesh faces away and is dropped after one dot product) and a vertex (projected for
#: every particle). Measured on the Panda clustered on 1 px cells (31,052 triangles,
#: 13,776 vertices; the same meshes unwelded, 93,156 vertices): µs per evaluation
#: 71.0 as they are (75 % open), 59.7 all culled, 122.9 unwelded and culled, so a
#: culled triangle about 1.45 ns, a vertex 0.80, an unculled triangle 1.95.
UNCULLED_COST = 1.35
VERTEX_COST = 0.55

#: The fractions of the budget that the bodies' summed errors are held to, in turn,
#: until the chosen meshes measured together meet the budget (the last: none).
SHRINK_STEPS = (1.0, 0.85, 0.7, 0.55, 0.4, 0.25, 0.1, 0.0)

#: Renders meshes at the calibration configurations: (N, H, W) depths, inf where empty.
RenderMeshes = Callable[[RobotMeshes], np.ndarray]


@dataclass(frozen=True)
class BodyOption:
    """One way to render a body: ``cell_px`` (None: its own meshes), ``culled``, its
    ``triangles`` and ``vertices``, and the wrong pixels it leaves on the calibration
    images."""

    body: int
    cell_px: float | None
    culled: bool
    triangles: int
    vertices: int
    wrong_px: int

    @property
    def cost(self) -> float:
        """In culled triangles (:data:`UNCULLED_COST`, :data:`VERTEX_COST`)."""
        return (self.triangles * (1.0 if self.culled else UNCULLED_COST)
                + self.vertices * VERTEX_COST)


@dataclass(frozen=True)
class MeasuredDetail:
    """The chosen meshes, the option of each body, and how the chosen meshes agree with
    the full ones on the calibration images (all bodies rendered together)."""

    meshes: RobotMeshes
    options: tuple[BodyOption, ...]
    robot_px: int
    wrong_px: int

    @property
    def agreement(self) -> float:
        """The fraction of the full meshes' robot pixels that the chosen meshes render
        with the same label and depth (1 if the calibration images show no robot)."""
        return 1.0 - self.wrong_px / max(1, self.robot_px)


def wrong_pixels(depth: np.ndarray, reference: np.ndarray, tolerance_m: float) -> np.ndarray:
    """Pixels whose robot/background label differs, or both robot and depth differs by
    more than ``tolerance_m``."""
    hit, hit_ref = np.isfinite(depth), np.isfinite(reference)
    both = hit & hit_ref
    far = np.zeros_like(both)
    far[both] = np.abs(depth[both] - reference[both]) > tolerance_m
    return (hit ^ hit_ref) | far


def _variants(option: BodyMesh) -> list[tuple[bool, BodyMesh]]:
    """(culled, mesh): as it is, and with culling imposed if it is open."""
    v, t, closed = option
    if np.all(closed):
        return [(True, option)]
    return [(False, option), (True, (v, t, np.ones(len(t), bool)))]


def body_options(parts: dict[int, BodyMesh], render: RenderMeshes, names: list[str],
                 cells_m: dict[float, float], min_reduction: float,
                 tolerance_m: float) -> dict[int, list[tuple[BodyOption, BodyMesh]]]:
    """Every body's options: (:class:`BodyOption`, its mesh) pairs, its own meshes as
    read first. ``cells_m``: cell width in m by cell width in px."""
    alone = {b: render(join_bodies({b: part}, names)) for b, part in parts.items()}
    covers = sum(np.isfinite(image).astype(np.int32) for image in alone.values())
    options = {}
    for b, part in parts.items():
        others = (covers - np.isfinite(alone[b])) > 0
        meshes = [(None, part)]
        for cell_px, cell_m in sorted(cells_m.items(), reverse=True):
            clustered = cluster_body(part, cell_m, min_reduction)
            if clustered is not None:
                meshes.append((cell_px, clustered))
        options[b] = []
        for cell_px, mesh in meshes:
            for culled, variant in _variants(mesh):
                if variant is part:
                    wrong = 0  # the body's meshes as read: the reference itself
                else:
                    image = render(join_bodies({b: variant}, names))
                    wrong = int((wrong_pixels(image, alone[b], tolerance_m)
                                 & ~others).sum())
                options[b].append((BodyOption(b, cell_px, culled, len(variant[1]),
                                           len(variant[0]), wrong),
                                   variant))
    return options


def _best_switch(wrong: list[list[int]], cost: list[list[float]], chosen: list[int],
                 ratio: Callable[[int, float], float | None]) -> tuple[int, int] | None:
    """The (body, option) whose switch from its chosen option has the largest
    ``ratio(removed, added)`` (wrong pixels it removes, cost it adds; None: not a
    candidate), or None if no switch is a candidate."""
    best, best_ratio = None, -np.inf
    for b, (w, c) in enumerate(zip(wrong, cost)):
        for k in range(len(w)):
            r = ratio(w[chosen[b]] - w[k], c[k] - c[chosen[b]])
            if r is not None and r > best_ratio:
                best, best_ratio = (b, k), r
    return best


def _refining(removed: int, added: float) -> float | None:
    """A switch that removes wrong pixels, by pixels removed per cost added (a cheaper
    one first)."""
    if removed <= 0:
        return None
    return np.inf if added <= 0 else removed / added


def choose_options(wrong: list[list[int]], cost: list[list[float]],
                   budget: float) -> list[int]:
    """For each body (``wrong[b][k]``, ``cost[b][k]``: its option k's wrong pixels and
    cost), the option to take: from each body's cheapest, the switches that remove the
    most wrong pixels per cost added until the wrong pixels add up to at most
    ``budget``; then, while one fits, the cheaper option that saves the most cost per
    wrong pixel it adds. No single body can then take a cheaper option without
    exceeding the budget."""
    chosen = [min(range(len(c)), key=lambda k, c=c, w=w: (c[k], w[k]))
              for w, c in zip(wrong, cost)]

    def total() -> int:
        return sum(w[k] for w, k in zip(wrong, chosen))

    while total() > budget:
        step = _best_switch(wrong, cost, chosen, _refining)
        if step is None:
            return chosen
        chosen[step[0]] = step[1]

    spare = budget - total()

    def coarsening(removed: int, added: float) -> float | None:
        if added >= 0 or -removed > spare:  # not cheaper, or over the budget
            return None
        return np.inf if removed >= 0 else added / removed  # cost saved per pixel added

    while (step := _best_switch(wrong, cost, chosen, coarsening)) is not None:
        chosen[step[0]] = step[1]
        spare = budget - total()
    return chosen


def measure_detail(source: RobotMeshes, render: RenderMeshes, cells_m: dict[float, float],
                   max_disagreement: float, min_reduction: float = 2.0,
                   tolerance_m: float = 0.01) -> MeasuredDetail:
    """The level of detail of the module docstring for ``source`` (see there), measured
    on the images ``render`` makes. ``cells_m``: the ladder of cells, their width in m
    by their width in px."""
    if not 0.0 <= max_disagreement < 1.0:
        raise ValueError(f"max_disagreement must be in [0, 1), got {max_disagreement}")
    options = body_options(split_bodies(source), render, source.names, cells_m,
                           min_reduction, tolerance_m)
    bodies = sorted(options)
    wrong = [[o.wrong_px for o, _ in options[b]] for b in bodies]
    cost = [[o.cost for o, _ in options[b]] for b in bodies]
    reference = render(source)
    robot_px = int(np.isfinite(reference).sum())
    budget = max_disagreement * robot_px
    # The bodies' errors may fall on the same pixels, or on pixels another body's
    # simplification uncovers: measure the choice with all bodies together, and choose
    # again for a smaller sum while that measurement is over the budget.
    for shrink in SHRINK_STEPS:
        chosen = choose_options(wrong, cost, shrink * budget)
        meshes = join_bodies({b: options[b][k][1] for b, k in zip(bodies, chosen)},
                             source.names)
        wrong_px = int(wrong_pixels(render(meshes), reference, tolerance_m).sum())
        if wrong_px <= budget:
            break
    return MeasuredDetail(meshes, tuple(options[b][k][0] for b, k in zip(bodies, chosen)),
                          robot_px, wrong_px)
