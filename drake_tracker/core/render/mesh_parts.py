"""The robot's meshes as the rasteriser reads them: grouped into parts, with bounds.

A part is a spatially compact group of at most :data:`PART_TRIANGLES` triangles of one
body, with its own vertices and bounding sphere. The rasteriser culls, and decides
whether near-plane clipping is needed, per part rather than per body: a large body
(a torso, a base) of which only a corner is in view, or that reaches behind the camera,
then costs only the parts that are in view, not all its triangles on the slow path.

Parts are made by splitting each body's triangles at the median of their centroids
along the longest axis of their bounding box, recursively, until a part is small enough.
Vertices shared by two parts are duplicated, so each part transforms only its own.
"""

from __future__ import annotations

import numpy as np

from drake_tracker.core.render.meshes import RobotMeshes

#: The largest number of triangles in one part.
PART_TRIANGLES = 64


def split_into_parts(centroids: np.ndarray, max_triangles: int = PART_TRIANGLES
                     ) -> list[np.ndarray]:
    """Indices of ``centroids`` (T, 3) in groups of at most ``max_triangles``, each the
    result of median splits along the longest axis of the group's bounding box."""
    if max_triangles < 1:
        raise ValueError(f"max_triangles must be >= 1, got {max_triangles}")
    pending = [np.arange(len(centroids))]
    parts = []
    while pending:
        group = pending.pop()
        if len(group) <= max_triangles:
            if len(group):
                parts.append(group)
            continue
        points = centroids[group]
        axis = int(np.argmax(points.max(axis=0) - points.min(axis=0)))
        order = group[np.argsort(points[:, axis], kind="stable")]
        half = len(order) // 2
        pending += [order[half:], order[:half]]
    return parts


def render_tables(meshes: RobotMeshes, num_bodies: int,
                  max_triangles: int = PART_TRIANGLES) -> tuple:
    """The meshes regrouped into parts (see the module docstring), with per-part
    bounding spheres and per-triangle planes, as the arguments of
    :func:`~drake_tracker.core.render.rasterize.render_particle` after ``zbuf`` and ``X``:
    ``(vertices, triangles, part_body, part_vertex_start, part_tri_start, centers,
    radii, normals, offsets, closed)``."""
    vertices = np.asarray(meshes.vertices, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(meshes.triangles, dtype=np.int64).reshape(-1, 3)
    tri_body = np.asarray(meshes.triangle_body, dtype=np.int64).reshape(-1)
    vertex_body = np.asarray(meshes.vertex_body, dtype=np.int64).reshape(-1)
    closed = (np.zeros(len(triangles), bool) if meshes.triangle_closed is None
              else np.asarray(meshes.triangle_closed, bool).reshape(-1))
    if np.any(vertex_body[triangles] != tri_body[:, None]):
        raise ValueError("each triangle's vertices must belong to the triangle's body")
    if len(tri_body) and (tri_body.min() < 0 or tri_body.max() >= num_bodies):
        raise ValueError(f"triangle bodies must lie in [0, {num_bodies})")
    centroids = vertices[triangles].mean(axis=1)
    part_vertices, part_triangles, part_closed, part_body = [], [], [], []
    vertex_start, tri_start = [0], [0]
    for body in range(num_bodies):
        in_body = np.flatnonzero(tri_body == body)
        for group in split_into_parts(centroids[in_body], max_triangles):
            tris = triangles[in_body[group]]
            used, local = np.unique(tris, return_inverse=True)
            part_vertices.append(vertices[used])
            part_triangles.append(local.reshape(-1, 3) + vertex_start[-1])
            part_closed.append(closed[in_body[group]])
            part_body.append(body)
            vertex_start.append(vertex_start[-1] + len(used))
            tri_start.append(tri_start[-1] + len(group))
    if part_body:
        vertices = np.ascontiguousarray(np.vstack(part_vertices))
        triangles = np.ascontiguousarray(np.vstack(part_triangles), dtype=np.int64)
        closed = np.ascontiguousarray(np.concatenate(part_closed))
    else:
        vertices, triangles = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
        closed = np.zeros(0, bool)
    vertex_start = np.asarray(vertex_start, dtype=np.int64)
    centers = np.zeros((len(part_body), 3))
    radii = np.zeros(len(part_body))
    for p in range(len(part_body)):
        v = vertices[vertex_start[p]:vertex_start[p + 1]]
        centers[p] = 0.5 * (v.min(axis=0) + v.max(axis=0))
        radii[p] = np.linalg.norm(v - centers[p], axis=1).max() * (1.0 + 1e-9) + 1e-9
    p0, p1, p2 = (vertices[triangles[:, k]] for k in range(3))
    normals = np.ascontiguousarray(np.cross(p1 - p0, p2 - p0))
    offsets = np.einsum("ij,ij->i", normals, p0)
    return (vertices, triangles, np.asarray(part_body, dtype=np.int64), vertex_start,
            np.asarray(tri_start, dtype=np.int64), centers, radii, normals, offsets, closed)
