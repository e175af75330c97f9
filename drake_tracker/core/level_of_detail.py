"""A level of detail of the robot's meshes at the scale of the image's pixels.

CAD meshes have tens of thousands of triangles, most far smaller than a pixel of the
tracker's 80x60 image: rasterising them costs per triangle, not per pixel. Built once per
image size, from the meshes read from SceneGraph (nothing per robot), each body's mesh is
simplified by quadric edge collapse (the ``pyfqmr`` library) with a geometric tolerance of
a fraction of a pixel's footprint at a reference depth: an edge is collapsed only while
the quadric error of the merged vertex (the sum of its squared distances to the original
planes it stands for) stays below the tolerance squared, so the surface moves by less
than the tolerance. A body keeps its original mesh when simplification would not at least
halve its triangles (Drake's primitives, tessellated coarsely already).

Measured on the generated CAD-like Apollo (``models/generate_hires.py``,
``write_apollo_hires``, 54,720 triangles): 10,360 triangles at 80x60, 12,058 at 160x120;
against Drake's RenderEngineVtk on the full meshes, well within the tested agreement
(``tests/test_level_of_detail.py``). The library refuses collapses that would leave
near-degenerate triangles, so long slivers (cylinder sides, fillet strips) stay: the
reduction is 4.5-5x where an ideal decimation would reach far more.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_tracker.core.camera import CameraIntrinsics
from drake_tracker.core.geometry import RobotMeshes, orient_closed_mesh


@dataclass(frozen=True)
class LevelOfDetail:
    """How finely the meshes are kept for an image size.

    ``tolerance_px``: the largest surface displacement allowed, in pixels, for geometry at
    ``reference_depth_m`` from the camera (closer geometry sees it larger, in proportion).
    ``min_reduction``: a body is simplified only if its triangle count drops at least
    this many times.
    """

    tolerance_px: float = 0.5
    reference_depth_m: float = 0.5
    min_reduction: float = 2.0

    def __post_init__(self):
        if not (self.tolerance_px > 0 and self.reference_depth_m > 0
                and self.min_reduction >= 1):
            raise ValueError(f"LevelOfDetail needs tolerance_px > 0, reference_depth_m > 0 "
                             f"and min_reduction >= 1, got {self}")

    def tolerance_m(self, intrinsics: CameraIntrinsics) -> float:
        """The tolerance in metres: ``tolerance_px`` pixels at ``reference_depth_m``."""
        focal = max(float(intrinsics.fx), float(intrinsics.fy))
        return self.tolerance_px * self.reference_depth_m / focal


def simplify_mesh(vertices: np.ndarray, triangles: np.ndarray,
                  tolerance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge-collapse simplification keeping every merged vertex's quadric error
    (sum of squared distances to the planes it represents) below ``tolerance_m``².
    Vertices at the same position are welded first; open borders are preserved.

    The library's threshold schedule ``alpha * (iteration + K) ** aggressiveness`` is
    held constant at ``tolerance_m``² (aggressiveness 0), with a target of 4 triangles,
    so the tolerance, not a triangle budget, ends the simplification."""
    import pyfqmr

    _, first, inverse = np.unique(np.round(np.asarray(vertices, float), 9), axis=0,
                                  return_index=True, return_inverse=True)
    welded = np.ascontiguousarray(np.asarray(vertices, float)[first])
    tris = inverse.reshape(-1)[np.asarray(triangles, np.int64)]
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    tris = np.ascontiguousarray(tris[keep], dtype=np.int32)
    simplifier = pyfqmr.Simplify()
    simplifier.setMesh(welded, tris)
    simplifier.simplify_mesh(target_count=4, update_rate=1, aggressiveness=0.0,
                             alpha=float(tolerance_m) ** 2, K=3, max_iterations=200,
                             preserve_border=True, verbose=False)
    v, t, _ = simplifier.getMesh()
    return np.asarray(v, float), np.asarray(t, np.int64).reshape(-1, 3)


def level_of_detail(meshes: RobotMeshes, tolerance_m: float,
                    min_reduction: float = 2.0) -> RobotMeshes:
    """``meshes`` with each body's triangles simplified to ``tolerance_m`` (see
    :func:`simplify_mesh`) where that divides the body's triangle count by at least
    ``min_reduction``; closedness (for back-face culling) is re-derived per body."""
    if tolerance_m <= 0:
        raise ValueError(f"level_of_detail: tolerance_m must be > 0, got {tolerance_m}")
    closed_in = (np.zeros(meshes.num_triangles, bool) if meshes.triangle_closed is None
                 else np.asarray(meshes.triangle_closed, bool))
    verts, tris, vbody, tbody, closed = [], [], [], [], []
    offset = 0
    for body in np.unique(meshes.triangle_body):
        t_mask = meshes.triangle_body == body
        t = np.asarray(meshes.triangles[t_mask], np.int64)
        used = np.unique(t)
        v = np.asarray(meshes.vertices[used], float)
        t = np.searchsorted(used, t)
        c = closed_in[t_mask]
        v_new, t_new = simplify_mesh(v, t, tolerance_m)
        if len(t_new) * min_reduction <= len(t):
            v, (t, is_closed) = v_new, orient_closed_mesh(v_new, t_new)
            c = np.full(len(t), is_closed)
        verts.append(v)
        tris.append(t + offset)
        vbody.append(np.full(len(v), body, np.int32))
        tbody.append(np.full(len(t), body, np.int32))
        closed.append(c)
        offset += len(v)
    if not verts:
        return meshes
    return RobotMeshes(vertices=np.vstack(verts), triangles=np.vstack(tris).astype(np.int32),
                       vertex_body=np.concatenate(vbody), triangle_body=np.concatenate(tbody),
                       names=list(meshes.names), triangle_closed=np.concatenate(closed))
