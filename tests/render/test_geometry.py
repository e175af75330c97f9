"""Tessellation of Drake shapes: closed, outward-wound surfaces the renderer may cull."""

import numpy as np
import pytest

from drake_tracker.core.render import meshes as geometry
from drake_tracker.robot.model import build_tracker_model, robot_preset


def _volume(v, t):
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


SHAPES = {
    "box": (geometry.box_mesh([0.1, 0.2, 0.3]), 0.1 * 0.2 * 0.3),
    "cylinder": (geometry.cylinder_mesh(0.05, 0.2), np.pi * 0.05**2 * 0.2),
    "sphere": (geometry.sphere_mesh(0.05), 4 / 3 * np.pi * 0.05**3),
    "capsule": (geometry.capsule_mesh(0.05, 0.2), np.pi * 0.05**2 * (0.2 + 4 / 3 * 0.05)),
    "ellipsoid": (geometry.ellipsoid_mesh(0.05, 0.1, 0.15), 4 / 3 * np.pi * 0.05 * 0.1 * 0.15),
}


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_primitives_are_closed_and_wound_outward(name):
    (v, t), exact = SHAPES[name]
    oriented, closed = geometry.orient_closed_mesh(v, t)
    assert closed
    np.testing.assert_array_equal(oriented, t)  # already outward: unchanged
    assert _volume(v, t) == pytest.approx(exact, rel=0.06)


def test_inward_and_mirrored_meshes_are_reoriented_per_component():
    v, t = geometry.box_mesh([1.0, 1.0, 1.0])
    v2 = np.vstack([v, v + 3.0])
    t2 = np.vstack([t[:, ::-1], t + len(v)])  # first box inward, second outward
    oriented, closed = geometry.orient_closed_mesh(v2, t2)
    assert closed
    np.testing.assert_array_equal(oriented[len(t):], t + len(v))
    assert _volume(v2, oriented[:len(t)]) == pytest.approx(1.0)
    mirrored, closed = geometry.orient_closed_mesh(v * [-1.0, 1.0, 1.0], t)
    assert closed and _volume(v * [-1.0, 1.0, 1.0], mirrored) == pytest.approx(1.0)


def test_open_or_inconsistent_meshes_are_not_closed():
    v, t = geometry.box_mesh([1.0, 1.0, 1.0])
    assert not geometry.orient_closed_mesh(v, t[:-1])[1]  # a hole
    flipped = t.copy()
    flipped[0] = flipped[0, ::-1]
    assert not geometry.orient_closed_mesh(v, flipped)[1]  # one face wound inconsistently


def test_obj_with_repeated_vertices_is_closed(tmp_path):
    v, t = geometry.box_mesh([0.1, 0.2, 0.3])
    lines = []
    for k, tri in enumerate(t):  # every face gets its own copies of the vertices
        lines += [f"v {x} {y} {z}" for x, y, z in v[tri]]
        lines.append(f"f {3 * k + 1}//1 {3 * k + 2}//1 {3 * k + 3}//1")
    path = tmp_path / "box.obj"
    path.write_text("\n".join(lines) + "\n")
    ov, ot = geometry.load_obj(path)
    assert len(ov) == 3 * len(t)
    assert geometry.orient_closed_mesh(ov, ot)[1]


@pytest.mark.parametrize("robot", ["apollo", "arm6"])
def test_robot_meshes_are_closed(robot):
    model = build_tracker_model(robot_preset(robot))
    meshes = geometry.extract_robot_meshes(model.plant, model.scene_graph)
    assert meshes.triangle_closed is not None
    assert meshes.triangle_closed.shape == (meshes.num_triangles,)
    assert meshes.triangle_closed.all()  # primitives and the OBJ gripper
