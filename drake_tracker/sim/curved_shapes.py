"""The simulated camera's curved shapes as meshes of a stated accuracy.

RenderEngineVtk tessellates a Sphere into about 5000 triangles (50 segments around, 50
from pole to pole), more than the camera needs: on this project's software EGL each of
Apollo's three spheres cost about 1 ms of every render, and the camera renders twice
per frame. :func:`tessellate_curved_perception` gives every Sphere, Cylinder, Capsule
and Ellipsoid with a perception role a triangle mesh in its place, for the renderer
only: the original keeps its other roles (Meshcat still draws the true shape), and
the mesh has the original's frame, pose and perception properties.

Each mesh is the lathe of ``core.geometry`` (vertex radius compensated, so that the
polygon straddles the true surface), with the fewest segments around the axis, a
multiple of 4, for which no point of it is farther than ``tolerance_m`` from the true
surface: :func:`sphere_deviation` measures a unit sphere's lathe, the worst of the
four kinds (a cylinder's side deviates less, and a capsule is a sphere's halves on
a cylinder), and scales it by the shape's largest radius. A shape that would need
more than ``MAX_SEGMENTS`` (RenderEngineVtk's own have 50) keeps Drake's own.
"""

from __future__ import annotations

import functools

import numpy as np
from pydrake.common import MemoryFile
from pydrake.geometry import (
    Capsule,
    Cylinder,
    Ellipsoid,
    GeometryInstance,
    InMemoryMesh,
    Mesh,
    PerceptionProperties,
    Role,
    SceneGraph,
    Shape,
    Sphere,
)

from drake_tracker.core.render.meshes import sphere_mesh, tessellate_shape

#: The shapes replaced.
CURVED_SHAPES = (Sphere, Cylinder, Capsule, Ellipsoid)
#: The most segments around the axis a replacement may have: RenderEngineVtk's own
#: spheres and cylinders have 50, so a replacement never has more triangles than the
#: shape it replaces. A shape that would need more keeps Drake's own.
MAX_SEGMENTS = 48
#: Barycentric sampling density of :func:`surface_points`.
_SAMPLES_PER_EDGE = 16


def surface_points(vertices: np.ndarray, triangles: np.ndarray,
                   samples_per_edge: int = _SAMPLES_PER_EDGE) -> np.ndarray:
    """Points spread over every triangle (its vertices, edges and inside, on a
    barycentric grid of ``samples_per_edge`` steps): (T * S, 3)."""
    g = np.linspace(0.0, 1.0, samples_per_edge + 1)
    a, b = np.meshgrid(g, g, indexing="ij")
    keep = a + b <= 1.0 + 1e-12
    bary = np.column_stack([a[keep], b[keep], 1.0 - a[keep] - b[keep]])
    return np.einsum("sk,tki->tsi", bary, vertices[triangles]).reshape(-1, 3)


@functools.cache
def sphere_deviation(segments: int) -> float:
    """The largest distance from the unit sphere of the points of its ``segments``
    lathe (``core.geometry.sphere_mesh``), outwards or inwards."""
    v, t = sphere_mesh(1.0, segments)
    return float(np.abs(np.linalg.norm(surface_points(v, t), axis=1) - 1.0).max())


def largest_radius_m(shape: Shape) -> float:
    """The radius that scales a curved shape's tessellation error (m)."""
    if isinstance(shape, Ellipsoid):
        return max(shape.a(), shape.b(), shape.c())
    return shape.radius()


def _fewest_segments(shape: Shape, tolerance_m: float) -> int | None:
    """:func:`segments_for`'s count, or None when it would exceed ``MAX_SEGMENTS``."""
    radius = largest_radius_m(shape)
    for segments in range(8, MAX_SEGMENTS + 1, 4):
        if sphere_deviation(segments) * radius <= tolerance_m:
            return segments
    return None


def segments_for(shape: Shape, tolerance_m: float) -> int:
    """The fewest segments around the axis, a multiple of 4 from 8, whose lathe of
    ``shape`` stays within ``tolerance_m`` of its surface."""
    if not tolerance_m > 0:
        raise ValueError(f"tolerance_m must be > 0, got {tolerance_m}")
    segments = _fewest_segments(shape, tolerance_m)
    if segments is None:
        raise ValueError(f"a {type(shape).__name__} of radius {largest_radius_m(shape)} m "
                         f"needs more than {MAX_SEGMENTS} segments for a tolerance of "
                         f"{tolerance_m} m")
    return segments


def obj_text(vertices: np.ndarray, triangles: np.ndarray) -> str:
    """A Wavefront OBJ of the mesh with area-weighted vertex normals (Drake's OBJ reader
    requires normals)."""
    corners = vertices[triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in vertices]
    lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in normals]
    lines += ["f " + " ".join(f"{i + 1}//{i + 1}" for i in tri) for tri in triangles]
    return "\n".join(lines) + "\n"


def _tessellated_mesh(shape: Shape, segments: int, name: str) -> Mesh:
    """``shape``'s lathe of ``segments`` as an in-memory OBJ Mesh."""
    v, t = tessellate_shape(shape, segments)
    return Mesh(InMemoryMesh(mesh_file=MemoryFile(obj_text(v, t), ".obj",
                                                  f"{name} (tessellated)")))


def tessellate_curved_perception(scene_graph: SceneGraph, tolerance_m: float) -> int:
    """Gives every curved shape with a perception role in ``scene_graph`` (its model,
    before a Context is made) a perception-only mesh within ``tolerance_m`` of its
    surface in its place (see the module doc). Returns how many were replaced; 0
    tolerance replaces none, and a shape that would need more than ``MAX_SEGMENTS``
    (at 0.3 mm, a sphere of radius over 9 cm) keeps Drake's own."""
    if not tolerance_m >= 0:
        raise ValueError(f"tolerance_m must be >= 0, got {tolerance_m}")
    if tolerance_m == 0:
        return 0
    inspector = scene_graph.model_inspector()
    owner = {inspector.GetName(s): s for s in inspector.GetAllSourceIds()}
    replaced = 0
    for geometry_id in inspector.GetAllGeometryIds(Role.kPerception):
        shape = inspector.GetShape(geometry_id)
        if not isinstance(shape, CURVED_SHAPES):
            continue
        segments = _fewest_segments(shape, tolerance_m)
        if segments is None:
            continue  # too large for the tolerance: Drake's own shape is the better trade
        source_id = owner[inspector.GetOwningSourceName(geometry_id)]
        name = inspector.GetName(geometry_id)
        properties = PerceptionProperties(inspector.GetPerceptionProperties(geometry_id))
        instance = GeometryInstance(inspector.GetPoseInFrame(geometry_id),
                                    _tessellated_mesh(shape, segments, name),
                                    f"{name}_tessellated")
        frame_id = inspector.GetFrameId(geometry_id)
        scene_graph.RemoveRole(source_id, geometry_id, Role.kPerception)
        if frame_id == inspector.world_frame_id():
            new_id = scene_graph.RegisterAnchoredGeometry(source_id, instance)
        else:
            new_id = scene_graph.RegisterGeometry(source_id, frame_id, instance)
        scene_graph.AssignRole(source_id, new_id, properties)
        replaced += 1
    return replaced
