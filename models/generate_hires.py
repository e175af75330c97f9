"""Writes a robot with CAD-like meshes: Apollo with every visual an OBJ mesh.

For the likelihood's level-of-detail tests and the bench (``drake_tracker.robot.hires``):
the same links, joints, frames and shape poses as ``apollo.sdf``
(``generate_models.apollo_sdf``), with cylinders and spheres finely tessellated and
boxes with rounded edges, as a CAD export gives them. Nothing is committed as files:
``write_apollo_hires(folder)`` writes the SDF and its meshes on demand.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from drake_tracker.models.generate_models import apollo_sdf

from drake_tracker.core.render.meshes import cylinder_mesh, sphere_mesh


def _rounded_box_mesh(size, fillet: float, steps: int):
    """A box with edges and corners rounded by ``fillet`` (m), as CAD exports them: the
    faces of a cube grid, finely spaced within ``fillet`` of each edge (``steps``
    intervals), pushed out onto the Minkowski sum of the inner box and a sphere."""
    half = 0.5 * np.asarray(size, float)
    fillet = min(fillet, 0.45 * float(half.min()))
    inner = half - fillet
    ticks = []
    for h in half:
        fine = np.linspace(0.0, fillet, steps + 1)
        ticks.append(np.unique(np.concatenate([-h + fine, [0.0], h - fine[::-1]])))
    verts, tris = [], []
    for axis in range(3):
        a, b = (axis + 1) % 3, (axis + 2) % 3
        for sign in (-1.0, 1.0):
            ua, ub = np.meshgrid(ticks[a], ticks[b], indexing="ij")
            q = np.zeros(ua.shape + (3,))
            q[..., axis] = sign * half[axis]
            q[..., a] = ua
            q[..., b] = ub
            core = np.clip(q, -inner, inner)
            direction = q - core
            direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
            p = (core + fillet * direction).reshape(-1, 3)
            na, nb = ua.shape
            idx = np.arange(na * nb).reshape(na, nb) + sum(len(v) for v in verts)
            quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1)
            quads = quads.reshape(-1, 4)
            t = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
            # Counter-clockwise seen from outside: (a, b, axis) is right-handed.
            verts.append(p)
            tris.append(t if sign > 0 else t[:, ::-1])
    return np.vstack(verts), np.vstack(tris)


def _obj_text(vertices: np.ndarray, triangles: np.ndarray, comment: str) -> str:
    """OBJ text with welded vertices and area-weighted vertex normals."""
    _, first, inverse = np.unique(np.round(vertices, 9), axis=0, return_index=True,
                                  return_inverse=True)
    v = vertices[first]
    t = inverse.reshape(-1)[triangles]
    t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])]
    face = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    normals = np.zeros_like(v)
    for k in range(3):
        np.add.at(normals, t[:, k], face)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    lines = [f"# {comment}"]
    lines += [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in v]
    lines += [f"vn {x:.5f} {y:.5f} {z:.5f}" for x, y, z in normals]
    lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in t + 1]
    return "\n".join(lines) + "\n"


def write_apollo_hires(folder, segments: int = 96, fillet_steps: int = 5) -> Path:
    """Writes ``apollo_hires.sdf`` and its OBJ meshes into ``folder``; returns the SDF.

    The same robot as ``apollo.sdf`` (same links, joints, frames and shape poses), but
    every visual is an OBJ mesh as a CAD export would give it: cylinders and spheres with
    ``segments`` facets around, boxes with 1 cm rounded edges sampled by ``fillet_steps``
    rows. Defaults give 54,720 triangles; ``segments=48, fillet_steps=3`` 19,104.
    """
    folder = Path(folder)
    (folder / "meshes_hires").mkdir(parents=True, exist_ok=True)
    count = 0

    def replace(match) -> str:
        nonlocal count
        kind, body = match.group(1), match.group(2)
        numbers = [float(x) for x in re.findall(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?", body)]
        if kind == "box":
            v, t = _rounded_box_mesh(numbers, 0.01, fillet_steps)
        elif kind == "cylinder":
            v, t = cylinder_mesh(numbers[0], numbers[1], segments)
        else:
            v, t = sphere_mesh(numbers[0], segments)
        name = f"meshes_hires/part_{count:02d}_{kind}.obj"
        count += 1
        (folder / name).write_text(_obj_text(v, t, f"{kind} {numbers}, {len(t)} triangles"))
        return f"<geometry><mesh><uri>{name}</uri></mesh></geometry>"

    sdf = re.sub(r"<geometry><(box|cylinder|sphere)>(.*?)</\1></geometry>", replace,
                 apollo_sdf())
    path = folder / "apollo_hires.sdf"
    path.write_text(sdf.replace('<model name="apollo">', '<model name="apollo_hires">'))
    return path
