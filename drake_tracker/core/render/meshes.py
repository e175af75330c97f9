"""The robot's visual geometry as triangle meshes in body frames, read once from SceneGraph.

Drake shapes (Box, Sphere, Cylinder, Capsule, Ellipsoid, and OBJ Mesh/Convex) are
tessellated here so that the batched renderer only ever sees triangles. Curved shapes
use a modest tessellation whose vertex radius is enlarged slightly so that the polygon
is on average as far out as the true surface (half the error of an inscribed polygon).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from pydrake.geometry import SceneGraph, Shape
    from pydrake.multibody.plant import MultibodyPlant

#: Default number of segments around the axis of curved shapes.
DEFAULT_SEGMENTS = 14


@dataclass
class RobotMeshes:
    """Triangles of all visual geometries, each vertex in the frame of its body.

    ``vertices`` (V, 3) float64, ``triangles`` (T, 3) int32 indices into ``vertices``,
    ``vertex_body`` (V,) int32 BodyIndex of each vertex (all vertices of a triangle
    share a body), ``triangle_body`` (T,) int32, ``names`` the geometry names.
    ``triangle_closed`` (T,) bool: the triangle belongs to a closed, consistently oriented
    surface and is wound counter-clockwise seen from outside, so a renderer may cull it
    when it faces away from the camera (None: unknown, cull nothing).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    vertex_body: np.ndarray
    triangle_body: np.ndarray
    names: list[str] = field(default_factory=list)
    triangle_closed: np.ndarray | None = None

    @property
    def num_triangles(self) -> int:
        """T, the number of triangles."""
        return int(self.triangles.shape[0])


# ----------------------------------------------------------------------------- shapes


def _compensated(radius: float, segments: int) -> float:
    """Vertex radius of a regular polygon whose vertices and edge midpoints straddle
    ``radius`` symmetrically."""
    return 2.0 * radius / (1.0 + np.cos(np.pi / segments))


def _lathe(profile: list[tuple[float, float]], segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Surface of revolution about z of a profile [(radius, z), ...] from bottom to top.

    A ring of radius 0 becomes one vertex (a pole). Returns (vertices, triangles) with
    triangles wound counter-clockwise seen from outside.
    """
    angles = 2.0 * np.pi * np.arange(segments) / segments
    ca, sa = np.cos(angles), np.sin(angles)
    vertices: list[np.ndarray] = []
    rings: list[np.ndarray] = []  # vertex indices of each ring
    count = 0
    for radius, z in profile:
        if radius == 0.0:
            vertices.append(np.array([[0.0, 0.0, z]]))
            rings.append(np.array([count]))
            count += 1
        else:
            ring = np.column_stack([radius * ca, radius * sa, np.full(segments, z)])
            vertices.append(ring)
            rings.append(count + np.arange(segments))
            count += segments
    tris: list[list[int]] = []
    for lo, hi in zip(rings[:-1], rings[1:], strict=True):
        for k in range(segments):
            k1 = (k + 1) % segments
            if lo.size == 1 and hi.size == 1:
                continue
            if lo.size == 1:
                tris.append([lo[0], hi[k1], hi[k]])
            elif hi.size == 1:
                tris.append([lo[k], lo[k1], hi[0]])
            else:
                tris.append([lo[k], lo[k1], hi[k1]])
                tris.append([lo[k], hi[k1], hi[k]])
    return np.vstack(vertices), np.array(tris, dtype=np.int64)


def box_mesh(size: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """A box centred at the origin with edge lengths ``size`` (x, y, z; m): vertices (8, 3)
    and triangles (12, 3) int64, wound counter-clockwise seen from outside."""
    sx, sy, sz = 0.5 * np.asarray(size, float)
    v = np.array([[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)])
    # Vertex index = 4*ix + 2*iy + iz.
    faces = [
        (0, 1, 3, 2), (4, 6, 7, 5),  # -x, +x
        (0, 4, 5, 1), (2, 3, 7, 6),  # -y, +y
        (0, 2, 6, 4), (1, 5, 7, 3),  # -z, +z
    ]
    tris = []
    for a, b, c, d in faces:
        tris += [[a, b, c], [a, c, d]]
    return v, np.array(tris, dtype=np.int64)


def cylinder_mesh(radius: float, length: float, segments: int = DEFAULT_SEGMENTS
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A closed cylinder about z centred at the origin (z in ±length/2), ``segments`` around
    the axis, radius compensated (module doc): vertices (V, 3) and triangles (T, 3) int64,
    wound counter-clockwise seen from outside."""
    r = _compensated(radius, segments)
    h = 0.5 * length
    return _lathe([(0.0, -h), (r, -h), (r, h), (0.0, h)], segments)


def _sphere_profile(radius: float, segments: int, lat: int, z_shift: float = 0.0, half: int = 0):
    """Profile of a sphere (half=0), its lower (-1) or upper (+1) hemisphere, with
    ``lat`` latitude bands from pole to pole."""
    r = _compensated(radius, segments)
    out = []
    for i in range(lat + 1):
        theta = np.pi * i / lat  # 0 at the south pole
        if half == -1 and theta > np.pi / 2 + 1e-12:
            break
        if half == 1 and theta < np.pi / 2 - 1e-12:
            continue
        rad = 0.0 if i in (0, lat) else r * np.sin(theta)
        out.append((rad, -r * np.cos(theta) + z_shift))
    return out


def sphere_mesh(radius: float, segments: int = DEFAULT_SEGMENTS
                ) -> tuple[np.ndarray, np.ndarray]:
    """A sphere centred at the origin, ``segments`` around z and ``segments // 2`` (at least
    2) latitude bands, radius compensated: vertices (V, 3) and triangles (T, 3) int64,
    wound counter-clockwise seen from outside."""
    return _lathe(_sphere_profile(radius, segments, max(2, segments // 2)), segments)


def ellipsoid_mesh(a: float, b: float, c: float, segments: int = DEFAULT_SEGMENTS
                   ) -> tuple[np.ndarray, np.ndarray]:
    """An ellipsoid with semi-axes ``a``, ``b``, ``c`` along x, y, z: the unit
    :func:`sphere_mesh` scaled per axis; vertices (V, 3) and triangles (T, 3) int64."""
    v, t = sphere_mesh(1.0, segments)
    return v * np.array([a, b, c]), t


def capsule_mesh(radius: float, length: float, segments: int = DEFAULT_SEGMENTS
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A capsule about z centred at the origin: a cylinder of ``radius`` whose ``length`` is
    between the hemisphere centres (as Drake's Capsule), capped by two hemispheres;
    vertices (V, 3) and triangles (T, 3) int64, wound counter-clockwise seen from outside."""
    # Even latitude count so that the equator is a ring in both hemispheres.
    lat = 2 * max(1, -(-segments // 4))
    h = 0.5 * length
    lower = _sphere_profile(radius, segments, lat, -h, half=-1)
    upper = _sphere_profile(radius, segments, lat, +h, half=+1)
    return _lathe(lower + upper, segments)


def load_obj(path: str | Path, scale: ArrayLike = (1.0, 1.0, 1.0)
             ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a Wavefront OBJ file (``v`` and ``f`` lines only).

    Face entries may be ``a``, ``a/b``, ``a//c`` or ``a/b/c``, with negative indices
    counting from the end; polygons are fan-triangulated. ``scale`` multiplies x, y, z.
    """
    vertices: list[list[float]] = []
    tris: list[list[int]] = []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line_no, line in enumerate(f, start=1):
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                if len(parts) < 4:
                    raise ValueError(f"{path}:{line_no}: vertex needs 3 coordinates")
                vertices.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                idx = []
                for token in parts[1:]:
                    k = int(token.split("/")[0])
                    idx.append(k - 1 if k > 0 else len(vertices) + k)
                if len(idx) < 3:
                    raise ValueError(f"{path}:{line_no}: face needs at least 3 vertices")
                for j in range(1, len(idx) - 1):
                    tris.append([idx[0], idx[j], idx[j + 1]])
    v = np.array(vertices, dtype=float).reshape(-1, 3) * np.asarray(scale, float)
    t = np.array(tris, dtype=np.int64).reshape(-1, 3)
    if t.size and (t.min() < 0 or t.max() >= len(v)):
        raise ValueError(f"{path}: face index out of range")
    return v, t


def _mesh_scale(shape) -> np.ndarray:
    if hasattr(shape, "scale3"):
        return np.asarray(shape.scale3(), float)
    return np.full(3, float(shape.scale()))


def tessellate_shape(shape: Shape, segments: int = DEFAULT_SEGMENTS
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of a Drake Shape in its own geometry frame."""
    from pydrake.geometry import Box, Capsule, Convex, Cylinder, Ellipsoid, Mesh, Sphere

    if isinstance(shape, Box):
        return box_mesh([shape.width(), shape.depth(), shape.height()])
    if isinstance(shape, Sphere):
        return sphere_mesh(shape.radius(), segments)
    if isinstance(shape, Cylinder):
        return cylinder_mesh(shape.radius(), shape.length(), segments)
    if isinstance(shape, Capsule):
        return capsule_mesh(shape.radius(), shape.length(), segments)
    if isinstance(shape, Ellipsoid):
        return ellipsoid_mesh(shape.a(), shape.b(), shape.c(), segments)
    if isinstance(shape, Mesh | Convex):
        source = shape.source()
        if not source.is_path():
            raise ValueError(f"in-memory {type(shape).__name__} shapes are not supported")
        path = Path(source.path())
        if path.suffix.lower() != ".obj":
            raise ValueError(f"only OBJ meshes are supported, got {path}")
        return load_obj(path, _mesh_scale(shape))
    raise ValueError(f"unsupported Drake shape for rendering: {type(shape).__name__}")


# ----------------------------------------------------------------------------- orientation


def orient_closed_mesh(vertices: np.ndarray, triangles: np.ndarray,
                       decimals: int = 9) -> tuple[np.ndarray, bool]:
    """Winds a closed mesh counter-clockwise seen from outside, if it is closed.

    Vertices at the same position (to ``decimals``) are merged first, since OBJ files
    repeat positions for per-face normals. The mesh is closed and consistently oriented if
    every directed edge occurs exactly once and its reverse exactly once. Then each
    connected component whose signed volume is negative (wound inwards, or mirrored by a
    negative scale) has its triangles reversed. Returns ``(triangles, closed)``; an open
    or inconsistent mesh comes back unchanged with ``closed = False``.
    """
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if triangles.size == 0:
        return triangles, False
    _, weld = np.unique(np.round(np.asarray(vertices, float), decimals), axis=0,
                        return_inverse=True)
    weld = weld.reshape(-1)
    t = weld[triangles]
    if np.any((t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 2] == t[:, 0])):
        return triangles, False  # degenerate triangles: do not trust the topology
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    directed, counts = np.unique(edges, axis=0, return_counts=True)
    if np.any(counts != 1):
        return triangles, False
    reverse = np.unique(edges[:, ::-1], axis=0)
    if directed.shape != reverse.shape or np.any(directed != reverse):
        return triangles, False
    # Connected components over the welded vertices (union-find along edges).
    parent = np.arange(int(weld.max()) + 1)

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in directed:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            parent[ra] = rb
    component = np.array([find(int(a)) for a in t[:, 0]])
    v = np.asarray(vertices, float)
    p0, p1, p2 = v[triangles[:, 0]], v[triangles[:, 1]], v[triangles[:, 2]]
    centre = v.mean(axis=0)
    volume6 = np.einsum("ij,ij->i", p0 - centre, np.cross(p1 - centre, p2 - centre))
    out = triangles.copy()
    for c in np.unique(component):
        mask = component == c
        if volume6[mask].sum() < 0.0:
            out[mask] = out[mask][:, ::-1]
    return out, True


# ----------------------------------------------------------------------------- extraction


def extract_robot_meshes(plant: MultibodyPlant, scene_graph: SceneGraph,
                         segments: int = DEFAULT_SEGMENTS) -> RobotMeshes:
    """All perception-role geometries of the plant (illustration role if there are none),
    tessellated and expressed in the frames of the bodies they are attached to."""
    from pydrake.geometry import Role

    inspector = scene_graph.model_inspector()
    ids = list(inspector.GetAllGeometryIds(Role.kPerception))
    if not ids:
        ids = list(inspector.GetAllGeometryIds(Role.kIllustration))
    verts, tris, vbody, tbody, names, closed = [], [], [], [], [], []
    offset = 0
    for gid in ids:
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
        if body is None:  # geometry not registered by this plant
            continue
        v, t = tessellate_shape(inspector.GetShape(gid), segments)
        if t.size == 0:
            continue
        X_BG = inspector.GetPoseInFrame(gid).GetAsMatrix4()
        v = v @ X_BG[:3, :3].T + X_BG[:3, 3]
        t, is_closed = orient_closed_mesh(v, t)
        b = int(body.index())
        verts.append(v)
        tris.append(t + offset)
        vbody.append(np.full(len(v), b, dtype=np.int32))
        tbody.append(np.full(len(t), b, dtype=np.int32))
        names.append(inspector.GetName(gid))
        closed.append(np.full(len(t), is_closed))
        offset += len(v)
    if not verts:
        return RobotMeshes(np.zeros((0, 3)), np.zeros((0, 3), np.int32),
                           np.zeros(0, np.int32), np.zeros(0, np.int32), [],
                           np.zeros(0, bool))
    return RobotMeshes(
        vertices=np.vstack(verts),
        triangles=np.vstack(tris).astype(np.int32),
        vertex_body=np.concatenate(vbody),
        triangle_body=np.concatenate(tbody),
        names=names,
        triangle_closed=np.concatenate(closed),
    )
