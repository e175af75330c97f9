"""A level of detail of the robot's meshes at the scale of the image's pixels.

CAD meshes have tens of thousands of triangles, most far smaller than a pixel of the
tracker's 80x60 image: rasterising them costs per triangle, not per pixel. Built once per
image size, from the meshes read from SceneGraph (nothing per robot), each body's mesh is
simplified by vertex clustering (:func:`cluster_mesh`): the vertices are grouped by the
cell of a grid they fall in, each group becomes one vertex, and triangles whose corners
fall in fewer than three cells vanish. The cell is ``cell_px`` pixels wide at a reference
depth. The group's vertex is placed where the planes of its triangles meet best (the
minimiser of the summed squared distances to them, the quadric error of Garland and
Heckbert), kept inside the group's bounding box: edges and corners stay sharp, and no
point of the surface moves by more than a cell's diagonal.

Back-face culling stays exact in practice: the clustered mesh of a closed, outward-wound
body is the image of a closed surface under a map of its vertices, so each directed edge
occurs as often as its reverse (checked; a body for which it does not hold loses its
culling), and the nearest surface along a ray faces the camera.

Measured on the generated CAD-like Apollo (``models/generate_hires.py``,
``write_apollo_hires``, 54,720 triangles; 12 configurations against Drake's
RenderEngineVtk on the full meshes):

=================  ==========  ============  ============  ============
method             image       triangles     labels        depth p95
=================  ==========  ============  ============  ============
quadric collapse   80x60       10,360        99.87 %       0.60 mm
(pyfqmr, 0.5 px)   160x120     12,058        99.95 %       0.37 mm
clustering, 3 px   80x60       2,392         99.44 %       1.55 mm
(this module)      160x120     6,086         99.84 %       0.57 mm
=================  ==========  ============  ============  ============

Edge collapse stalls where it would leave slivers (cylinder sides, fillet strips), which
clustering removes; with the mean of each group as its vertex instead of the quadric
minimiser, 3 px cells agreed on only 98.5 % of the labels. On example-robot-data's
Panda (134,924 triangles, welded first) it is no better than clustering either: 98.2 %
of the labels at 4,764 triangles, against 98.6 % at clustering's 4,575.

One cell for all bodies does not fit every robot: the default :class:`LevelOfDetail`
chooses each body's cell by measurement (:mod:`drake_tracker.core.render.measured_detail`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_tracker.core.render.meshes import RobotMeshes
from drake_tracker.core.sensors.camera import CameraIntrinsics


@dataclass(frozen=True)
class LevelOfDetail:
    """How finely the meshes are kept for an image size.

    ``cell_px``: the clustering cell's width, in pixels, for geometry at
    ``reference_depth_m`` from the camera (closer geometry sees it larger, in proportion).
    ``min_reduction``: a body is simplified only if its triangle count drops at least
    this many times.

    ``max_disagreement``: if set, each body's cell is chosen by measurement
    (:mod:`drake_tracker.core.render.measured_detail`): the cheapest cells, from ``cell_px``
    down to ``finest_cell_px`` by factors of 1.5 (or the body's own meshes), that leave
    at most this fraction of the robot's pixels with another label, or a depth more than
    ``depth_tolerance_m`` off, than the full meshes give, on ``calibration_images``
    images of configurations about the robot's view configuration. None: ``cell_px``
    for every body.
    """

    cell_px: float = 3.0
    reference_depth_m: float = 0.5
    min_reduction: float = 2.0
    max_disagreement: float | None = 0.01
    finest_cell_px: float = 0.5
    calibration_images: int = 32
    depth_tolerance_m: float = 0.03

    def __post_init__(self):
        measured = self.max_disagreement is None or (
            0.0 <= self.max_disagreement < 1.0 and 0 < self.finest_cell_px <= self.cell_px
            and self.calibration_images >= 1 and self.depth_tolerance_m > 0)
        if not (self.cell_px > 0 and self.reference_depth_m > 0 and self.min_reduction >= 1
                and measured):
            raise ValueError(f"LevelOfDetail needs cell_px > 0, reference_depth_m > 0, "
                             f"min_reduction >= 1 and, when measured, max_disagreement "
                             f"in [0, 1), 0 < finest_cell_px <= cell_px, "
                             f"calibration_images >= 1 and depth_tolerance_m > 0; "
                             f"got {self}")

    def cell_m(self, intrinsics: CameraIntrinsics, cell_px: float | None = None) -> float:
        """The cell's width in metres: ``cell_px`` pixels at ``reference_depth_m``."""
        focal = max(float(intrinsics.fx), float(intrinsics.fy))
        return (self.cell_px if cell_px is None else cell_px) * self.reference_depth_m / focal

    def ladder_m(self, intrinsics: CameraIntrinsics) -> dict[float, float]:
        """The cells a measured level of detail chooses from: width in m by width in
        px, from ``cell_px`` down to ``finest_cell_px`` by factors of 1.5."""
        cells, cell = {}, float(self.cell_px)
        while cell >= self.finest_cell_px * (1 - 1e-9):
            cells[round(cell, 6)] = self.cell_m(intrinsics, cell)
            cell /= 1.5
        return cells


def _quadric_vertices(vertices: np.ndarray, triangles: np.ndarray, group: np.ndarray,
                      num_groups: int) -> np.ndarray:
    """Per group, the point minimising the area-weighted sum of squared distances to the
    planes of the triangles at its vertices, regularised towards the group's mean (so a
    flat or straight group, whose minimiser is not unique, gets its mean's projection),
    and clamped to the group's bounding box."""
    counts = np.bincount(group, minlength=num_groups).astype(float)
    mean = np.stack([np.bincount(group, vertices[:, k], num_groups) for k in range(3)], 1)
    mean /= counts[:, None]
    p0, p1, p2 = (vertices[triangles[:, k]] for k in range(3))
    normals = np.cross(p1 - p0, p2 - p0)  # length = twice the area: the weight
    length = np.linalg.norm(normals, axis=1)
    unit = np.divide(normals, length[:, None], out=np.zeros_like(normals),
                     where=length[:, None] > 0)
    offset = -np.einsum("ij,ij->i", unit, p0)
    # Plane quadric of a triangle: w (n.x + d)^2 = x' (w n n') x + 2 (w d n)' x + w d^2.
    A_t = length[:, None, None] * unit[:, :, None] * unit[:, None, :]
    b_t = -(length * offset)[:, None] * unit
    A = np.zeros((num_groups, 3, 3))
    b = np.zeros((num_groups, 3))
    for k in range(3):
        np.add.at(A, group[triangles[:, k]], A_t)
        np.add.at(b, group[triangles[:, k]], b_t)
    ridge = 1e-3 * np.trace(A, axis1=1, axis2=2) / 3.0 + 1e-300
    point = np.linalg.solve(A + ridge[:, None, None] * np.eye(3),
                            (b + ridge[:, None] * mean)[:, :, None])[:, :, 0]
    low = np.full((num_groups, 3), np.inf)
    high = np.full((num_groups, 3), -np.inf)
    np.minimum.at(low, group, vertices)
    np.maximum.at(high, group, vertices)
    return np.clip(point, low, high)


def cluster_mesh(vertices: np.ndarray, triangles: np.ndarray,
                 cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering of a mesh on a grid of ``cell_m`` cells (see the module
    docstring): (vertices, triangles) of the simplified mesh, its triangles wound as
    their originals. No point moves by more than the cell's diagonal."""
    if not cell_m > 0:
        raise ValueError(f"cluster_mesh: cell_m must be > 0, got {cell_m}")
    vertices = np.asarray(vertices, dtype=float).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(triangles) == 0:
        return vertices[:0], triangles
    cells = np.floor(vertices / cell_m).astype(np.int64)
    cells -= cells.min(axis=0)
    size = cells.max(axis=0) + 1
    # One integer per cell, in the lexicographic order of (x, y, z): np.unique over
    # rows, numbered the same, at a fraction of its cost.
    key = (cells[:, 0] * size[1] + cells[:, 1]) * size[2] + cells[:, 2]
    _, group = np.unique(key, return_inverse=True)
    group = group.reshape(-1)
    num_groups = int(group.max()) + 1
    positions = _quadric_vertices(vertices, triangles, group, num_groups)
    t = group[triangles]
    t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])]
    used, local = np.unique(t, return_inverse=True)
    return positions[used], local.reshape(-1, 3)


def edges_balanced(triangles: np.ndarray) -> bool:
    """Whether every directed edge of the mesh occurs as often as its reverse (a closed
    cycle of triangles: what back-face culling needs)."""
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    n = int(t.max()) + 1 if t.size else 1
    forward, n_forward = np.unique(edges[:, 0] * n + edges[:, 1], return_counts=True)
    backward, n_backward = np.unique(edges[:, 1] * n + edges[:, 0], return_counts=True)
    return (forward.shape == backward.shape and bool(np.all(forward == backward))
            and bool(np.all(n_forward == n_backward)))


BodyMesh = tuple[np.ndarray, np.ndarray, np.ndarray]
"""One body's mesh: vertices (V, 3), triangles (T, 3) into them, closed flags (T,)."""


def split_bodies(meshes: RobotMeshes) -> dict[int, BodyMesh]:
    """Each body's own mesh (vertices renumbered from 0), by body index."""
    closed = (np.zeros(meshes.num_triangles, bool) if meshes.triangle_closed is None
              else np.asarray(meshes.triangle_closed, bool))
    parts = {}
    for body in np.unique(meshes.triangle_body):
        mask = meshes.triangle_body == body
        t = np.asarray(meshes.triangles[mask], np.int64)
        used = np.unique(t)
        parts[int(body)] = (np.asarray(meshes.vertices[used], float),
                            np.searchsorted(used, t), closed[mask])
    return parts


def join_bodies(parts: dict[int, BodyMesh], names: list[str]) -> RobotMeshes:
    """The meshes of :func:`split_bodies`' parts together again (``names``: the geometry
    names of the meshes they came from)."""
    verts, tris, vbody, tbody, closed = [], [], [], [], []
    offset = 0
    for body, (v, t, c) in sorted(parts.items()):
        verts.append(v)
        tris.append(t + offset)
        vbody.append(np.full(len(v), body, np.int32))
        tbody.append(np.full(len(t), body, np.int32))
        closed.append(np.asarray(c, bool))
        offset += len(v)
    if not verts:
        return RobotMeshes(vertices=np.zeros((0, 3)), triangles=np.zeros((0, 3), np.int32),
                           vertex_body=np.zeros(0, np.int32),
                           triangle_body=np.zeros(0, np.int32), names=list(names),
                           triangle_closed=np.zeros(0, bool))
    return RobotMeshes(vertices=np.vstack(verts), triangles=np.vstack(tris).astype(np.int32),
                       vertex_body=np.concatenate(vbody), triangle_body=np.concatenate(tbody),
                       names=list(names), triangle_closed=np.concatenate(closed))


def cluster_body(part: BodyMesh, cell_m: float, min_reduction: float) -> BodyMesh | None:
    """One body's mesh clustered on ``cell_m`` cells (:func:`cluster_mesh`), or None if
    that does not divide its triangle count by ``min_reduction``. The result keeps
    back-face culling if all the body's triangles had it and its edges stay balanced
    (:func:`edges_balanced`)."""
    v, t, c = part
    v_new, t_new = cluster_mesh(v, t, cell_m)
    if len(t_new) * min_reduction > len(t):
        return None
    keeps_culling = bool(np.all(c)) and edges_balanced(t_new)
    return v_new, t_new, np.full(len(t_new), keeps_culling)


def level_of_detail(meshes: RobotMeshes, cell_m: float,
                    min_reduction: float = 2.0) -> RobotMeshes:
    """``meshes`` with each body's triangles clustered on ``cell_m`` cells where that
    divides the body's triangle count by at least ``min_reduction``
    (:func:`cluster_body`)."""
    if not cell_m > 0:
        raise ValueError(f"level_of_detail: cell_m must be > 0, got {cell_m}")
    parts = split_bodies(meshes)
    if not parts:
        return meshes
    for body, part in parts.items():
        parts[body] = cluster_body(part, cell_m, min_reduction) or part
    return join_bodies(parts, meshes.names)
