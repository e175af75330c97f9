"""The measured level of detail (core/render/measured_detail.py): the choice of options on
numbers against brute force, and on a robot with an open mesh (a cup the camera looks
into, where back-face culling would show the background through it) against Drake's
RenderEngineVtk."""

import itertools

import numpy as np
import pytest

from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.batched import BatchedDepthRenderer
from drake_tracker.core.render.configurations import random_configurations
from drake_tracker.core.render.level_of_detail import LevelOfDetail
from drake_tracker.core.render.measured_detail import choose_options, wrong_pixels
from drake_tracker.core.render.meshes import cylinder_mesh, sphere_mesh
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import (
    VIRTUAL_JOINT_NAMES,
    FrameOffset,
    RobotConfig,
    build_tracker_model,
)

URDF = """<?xml version="1.0"?>
<robot name="cup_and_ball">
  <link name="base_link">
    <visual><origin xyz="0.16 0 0.08"/><geometry><mesh filename="{ball}"/></geometry></visual>
  </link>
  <link name="cup_link">
    <visual><origin xyz="0 0 0.06"/><geometry><mesh filename="{cup}"/></geometry></visual>
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0"
      iyz="0"/></inertial>
  </link>
  <link name="tool"/>
  <joint name="cup_joint" type="revolute">
    <parent link="base_link"/><child link="cup_link"/><axis xyz="0 1 0"/>
    <limit lower="-0.6" upper="0.6" effort="10" velocity="2"/>
  </joint>
  <joint name="tool_joint" type="fixed">
    <parent link="cup_link"/><child link="tool"/><origin xyz="0 0 0.12"/>
  </joint>
</robot>
"""


def _write_obj(path, vertices, triangles):
    """An OBJ file with a normal per face (Drake's parser wants normals)."""
    p = vertices[triangles]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in vertices]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in normals]
    lines += [f"f {a + 1}//{k + 1} {b + 1}//{k + 1} {c + 1}//{k + 1}"
              for k, (a, b, c) in enumerate(triangles)]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def cup_model(tmp_path_factory):
    """A fine ball on the base (closed) and an open cup (a cylinder without its top cap)
    on a joint, seen from 0.55 m above, looking into the cup."""
    folder = tmp_path_factory.mktemp("cup")
    v, t = cylinder_mesh(0.06, 0.12, 96)
    top = np.all(v[t][:, :, 2] > 0.059, axis=1)
    _write_obj(folder / "cup.obj", v, t[~top])
    _write_obj(folder / "ball.obj", *sphere_mesh(0.07, 96))
    urdf = folder / "cup.urdf"
    urdf.write_text(URDF.format(ball=folder / "ball.obj", cup=folder / "cup.obj"))
    return build_tracker_model(RobotConfig(
        model_file=str(urdf), camera_frame="camera", end_effector_frame="tool",
        added_frames={"camera": FrameOffset(parent="base_link", xyz_m=[0.06, 0.0, 0.55],
                                            rpy_deg=[180.0, 0.0, 0.0])}))


INTRINSICS = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))


def test_culling_is_kept_off_where_the_camera_sees_into_an_open_mesh(cup_model):
    renderer = BatchedDepthRenderer(cup_model, INTRINSICS)
    measured = renderer.measured_detail
    assert measured is not None and measured.agreement >= 0.99
    body = {int(cup_model.plant.GetBodyByName(name).index()): name
            for name in ("base_link", "cup_link")}
    chosen = {body[o.body]: o for o in measured.options}
    assert not chosen["cup_link"].culled  # its inside is back faces, its floor too
    assert chosen["base_link"].culled and chosen["base_link"].cell_px is not None
    assert renderer.num_triangles < 0.3 * renderer.source_meshes.num_triangles
    # Against RenderEngineVtk on the full meshes, at configurations not calibrated on.
    q = random_configurations(cup_model, 12, seed=5, spread_rad=0.4,
                              center=np.zeros(cup_model.num_joints))
    ours = renderer.render(q)
    ref = make_renderer(cup_model, INTRINSICS, "drake").render(q)
    hit, hit_ref = np.isfinite(ours), np.isfinite(ref)
    assert (hit | hit_ref).sum() > 0.1 * ours.size
    assert 1.0 - (hit ^ hit_ref).sum() / (hit | hit_ref).sum() >= 0.99
    both = hit & hit_ref
    assert np.percentile(np.abs(ours[both] - ref[both]), 95) <= 0.01
    # The control: culling the cup would show what is behind it.
    culled = BatchedDepthRenderer(cup_model, INTRINSICS, detail=None)
    culled.meshes.triangle_closed[:] = True
    from drake_tracker.core.render.mesh_parts import render_tables
    from drake_tracker.core.simd.lane_render import lane_tables
    culled._tables = render_tables(culled.meshes, culled.kinematics.num_bodies)
    culled._lane_tables = lane_tables(culled._tables)
    assert wrong_pixels(culled.render(q), ref, 0.03).sum() > 0.05 * hit_ref.sum()


def test_a_robot_the_calibration_cannot_see_keeps_one_cell_and_says_so(cup_model):
    away = np.zeros((4, cup_model.num_joints))
    camera = cup_model.joint_names.index(VIRTUAL_JOINT_NAMES[0])
    away[:, camera] = 5.0  # the camera 5 m off: nothing in view
    with pytest.warns(UserWarning, match="calibration images show 0 robot pixels"):
        renderer = BatchedDepthRenderer(cup_model, INTRINSICS, detail_configurations=away)
    assert renderer.measured_detail is None
    uniform = BatchedDepthRenderer(cup_model, INTRINSICS,
                                   detail=LevelOfDetail(max_disagreement=None))
    assert renderer.num_triangles == uniform.num_triangles


def _brute_force(wrong, cost, budget):
    best = None
    for pick in itertools.product(*(range(len(w)) for w in wrong)):
        if sum(w[k] for w, k in zip(wrong, pick)) <= budget:
            total = sum(c[k] for c, k in zip(cost, pick))
            best = total if best is None else min(best, total)
    return best


@pytest.mark.parametrize("seed", range(40))
def test_choice_meets_the_budget_and_no_body_can_take_a_cheaper_option(seed):
    """Random bodies whose finer options cost more and err less (option 0: the full
    meshes, no error): the choice meets the budget, no single body can switch to a
    cheaper option within it, and it costs within 1.5x of the brute-force optimum."""
    rng = np.random.default_rng(seed)
    wrong, cost = [], []
    for _ in range(rng.integers(2, 6)):
        n = int(rng.integers(1, 5))
        c = np.sort(rng.uniform(1.0, 100.0, n + 1))[::-1].tolist()  # full: dearest
        wrong.append([0] + np.sort(rng.integers(0, 30, n)).tolist())
        cost.append(c)
    budget = float(rng.uniform(0, 40))
    chosen = choose_options(wrong, cost, budget)
    total = sum(w[k] for w, k in zip(wrong, chosen))
    assert total <= budget
    for b, (w, c) in enumerate(zip(wrong, cost)):
        for k in range(len(w)):
            if c[k] < c[chosen[b]]:
                assert total - w[chosen[b]] + w[k] > budget
    optimum = _brute_force(wrong, cost, budget)
    assert sum(c[k] for c, k in zip(cost, chosen)) <= 1.5 * optimum + 1e-9
