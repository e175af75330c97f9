"""A vendor's robot as it ships: a ROS-style package (package.xml) whose URDF refers to
STL meshes (and a DAE visual) through package:// URIs and has no camera or tool frame.
The frames come from the RobotConfig alone; the batched renderer must agree with Drake's
RenderEngineVtk on the converted meshes; model directives and an SDF load the package."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import (
    FrameOffset,
    RobotConfig,
    build_tracker_model,
    default_home_positions,
    load_robot_config,
)

trimesh = pytest.importorskip("trimesh", reason="the 'meshes' extra converts STL meshes")

PACKAGE = "tiny_arm_description"
#: Joint limits written into the URDF (rad): the home pose is their midpoints.
LIMITS = {"joint_1": (-2.0, 2.5), "joint_2": (-1.0, 1.6), "joint_3": (-2.4, 2.4)}
#: Camera 1.1 m in front of the base (+x), 0.45 m up, looking back along -x.
R_BASE_CAMERA = RotationMatrix(np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]))
CAMERA = FrameOffset(parent="base_link", xyz_m=[1.1, 0.0, 0.45],
                     rpy_deg=[float(a) for a in np.degrees(RollPitchYaw(R_BASE_CAMERA).vector())])
TOOL = FrameOffset(parent="link_3", xyz_m=[0.0, 0.02, 0.3], rpy_deg=[0.0, 90.0, 0.0])

URDF = """<?xml version="1.0"?>
<robot name="tiny_arm">
  <link name="base_link">{base}</link>
  <link name="link_1">{link1}</link>
  <link name="link_2">{link2}</link>
  <link name="link_3">{link3}</link>
  <joint name="joint_1" type="revolute">
    <parent link="base_link"/><child link="link_1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="{l1}" upper="{u1}" effort="10" velocity="2"/>
  </joint>
  <joint name="joint_2" type="revolute">
    <parent link="link_1"/><child link="link_2"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 1 0"/><limit lower="{l2}" upper="{u2}" effort="10" velocity="2"/>
  </joint>
  <joint name="joint_3" type="revolute">
    <parent link="link_2"/><child link="link_3"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 1 0"/><limit lower="{l3}" upper="{u3}" effort="10" velocity="2"/>
  </joint>
</robot>
"""


def _link(mesh: str, z: float) -> str:
    uri = f"package://{PACKAGE}/meshes/{mesh}.stl"
    geometry = f'<origin xyz="0 0 {z}"/><geometry><mesh filename="{uri}"/></geometry>'
    return (f"<visual>{geometry}</visual><collision>{geometry}</collision>"
            '<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" '
            'ixy="0" ixz="0" iyz="0"/></inertial>')


@pytest.fixture(scope="module")
def vendor(tmp_path_factory):
    """A workspace with the package, and an empty mesh cache."""
    root = tmp_path_factory.mktemp("vendor")
    package = root / "src" / PACKAGE
    (package / "meshes").mkdir(parents=True)
    (package / "urdf").mkdir()
    (package / "package.xml").write_text(
        f'<?xml version="1.0"?><package format="3"><name>{PACKAGE}</name>'
        "<version>1.0.0</version><description>test</description></package>")
    shapes = {
        "base": trimesh.creation.box((0.3, 0.3, 0.1)),
        "upper": trimesh.creation.cylinder(radius=0.05, height=0.3, sections=24),
        "fore": trimesh.creation.box((0.08, 0.06, 0.3)),
        "hand": trimesh.creation.box((0.06, 0.16, 0.12)),
    }
    for name, mesh in shapes.items():
        mesh.export(package / "meshes" / f"{name}.stl")
    shapes["hand"].export(package / "meshes" / "hand.dae")  # a COLLADA visual, as vendors
    hand = '<visual><origin xyz="0 0 0.33"/><geometry>' \
           f'<mesh filename="package://{PACKAGE}/meshes/hand.dae"/></geometry></visual>'
    limits = {f"{k}{i}": v for i, (lo, hi) in enumerate(LIMITS.values(), 1)
              for k, v in (("l", lo), ("u", hi))}
    (package / "urdf" / "tiny_arm.urdf").write_text(URDF.format(
        base=_link("base", 0.05), link1=_link("upper", 0.15), link2=_link("fore", 0.15),
        link3=_link("fore", 0.15) + hand, **limits))
    return root, package, root / "cache"


def _config(vendor, **changes) -> RobotConfig:
    root, _, cache = vendor
    config = RobotConfig(
        model_file=f"package://{PACKAGE}/urdf/tiny_arm.urdf",
        camera_frame="camera_optical", end_effector_frame="tool",
        added_frames={"camera_optical": CAMERA, "tool": TOOL},
        package_folders=[str(root / "src")], mesh_cache_dir=str(cache))
    for key, value in changes.items():
        setattr(config, key, value)
    return config


def test_config_frames_sit_where_the_config_says(vendor):
    model = build_tracker_model(_config(vendor))
    assert model.robot_joint_names == list(LIMITS)
    plant = model.plant
    context = plant.CreateDefaultContext()
    q = np.zeros(plant.num_positions())
    q[:3] = [0.4, -0.3, 0.7]
    plant.SetPositions(context, q)
    for frame, offset in ((model.nominal_camera_frame, CAMERA),
                          (model.end_effector_frame, TOOL)):
        X_WP = plant.GetFrameByName(offset.parent).CalcPoseInWorld(context)
        X_PF = RigidTransform(RollPitchYaw(np.radians(offset.rpy_deg)), offset.xyz_m)
        X_WF = frame.CalcPoseInWorld(context)
        np.testing.assert_allclose(X_WF.GetAsMatrix4(), (X_WP @ X_PF).GetAsMatrix4(),
                                   atol=1e-12)
    np.testing.assert_allclose(
        model.nominal_camera_frame.CalcPoseInWorld(context).rotation().matrix(),
        R_BASE_CAMERA.matrix(), atol=1e-12)  # the base is welded at the world origin


def test_batched_renderer_agrees_with_drake_on_the_converted_stl_meshes(vendor):
    model = build_tracker_model(_config(vendor))
    intrinsics = CameraIntrinsics.from_fov(160, 120, np.radians(60.0))
    q = np.zeros((3, model.num_joints))
    q[:, :3] = [[0.0, 0.0, 0.0], [0.5, 0.4, -0.6], [-0.8, -0.5, 1.0]]
    batched = make_renderer(model, intrinsics, "batched").render(q)
    drake = make_renderer(model, intrinsics, "drake").render(q)
    for a, b in zip(batched, drake, strict=True):
        hit_a, hit_b = np.isfinite(a), np.isfinite(b)
        either = (hit_a | hit_b).sum()
        assert hit_b.sum() > 500  # the arm fills a good part of the view
        assert (hit_a & hit_b).sum() / either >= 0.99
        both = hit_a & hit_b
        assert np.median(np.abs(a[both] - b[both])) < 0.002


def test_vendor_folder_is_untouched_and_meshes_convert_once(vendor):
    root, package, cache = vendor
    build_tracker_model(_config(vendor))
    converted = sorted(cache.glob("*.obj"))
    assert len(converted) == 4  # base, upper, fore (shared by two links), hand.dae
    stamps = [p.stat().st_mtime_ns for p in converted]
    build_tracker_model(_config(vendor))
    assert [p.stat().st_mtime_ns for p in sorted(cache.glob("*.obj"))] == stamps
    assert sorted(p.suffix for p in (package / "meshes").iterdir()) == [".dae"] + [".stl"] * 4


def test_model_file_path_finds_its_own_package_and_yaml_loads_the_config(vendor):
    _, package, cache = vendor
    text = f"""
model_file: {package / "urdf" / "tiny_arm.urdf"}
camera_frame: camera_optical
end_effector_frame: tool
mesh_cache_dir: {cache}
added_frames:
  camera_optical: {{parent: base_link, xyz_m: {CAMERA.xyz_m}, rpy_deg: {CAMERA.rpy_deg}}}
  tool: {{parent: link_3, xyz_m: [0, 0.02, 0.3], rpy_deg: [0, 90, 0]}}
"""
    model = build_tracker_model(load_robot_config(text))
    assert model.robot_joint_names == list(LIMITS)


def test_model_directives_load_the_package_and_add_the_frames(vendor, tmp_path):
    root, _, cache = vendor
    directives = tmp_path / "cell.dmd.yaml"
    directives.write_text(f"""directives:
- add_model:
    name: arm
    file: package://{PACKAGE}/urdf/tiny_arm.urdf
- add_weld: {{parent: world, child: arm::base_link}}
- add_frame:
    name: arm::camera_optical
    X_PF:
      base_frame: arm::base_link
      translation: {CAMERA.xyz_m}
      rotation: !Rpy {{deg: {CAMERA.rpy_deg}}}
""")
    config = _config(vendor, model_file=str(directives), added_frames={"tool": TOOL})
    model = build_tracker_model(config)
    reference = build_tracker_model(_config(vendor))
    context, ref_context = (m.plant.CreateDefaultContext() for m in (model, reference))
    X_CE = model.plant.CalcRelativeTransform(context, model.camera_frame,
                                             model.end_effector_frame)
    X_CE_ref = reference.plant.CalcRelativeTransform(ref_context, reference.camera_frame,
                                                     reference.end_effector_frame)
    np.testing.assert_allclose(X_CE.GetAsMatrix4(), X_CE_ref.GetAsMatrix4(), atol=1e-9)


def test_home_pose_is_the_middle_of_the_joint_limits(vendor):
    model = build_tracker_model(_config(vendor))
    home = default_home_positions(model.plant, model.robot_joint_names)
    np.testing.assert_allclose(home, [0.5 * (lo + hi) for lo, hi in LIMITS.values()])


def test_unknown_package_and_frame_are_named(vendor):
    with pytest.raises(ValueError, match=f"package '{PACKAGE}' is unknown.*package_paths"):
        build_tracker_model(_config(vendor, package_folders=[]))
    bad = {"camera_optical": FrameOffset(parent="no_such_link"), "tool": TOOL}
    with pytest.raises(ValueError, match="'no_such_link' does not exist.*link_3"):
        build_tracker_model(_config(vendor, added_frames=bad))


def test_sdf_with_package_uris_loads_the_stl_meshes_triangle_for_triangle(vendor, tmp_path):
    from drake_tracker.core.render.meshes import extract_robot_meshes

    root, package, _ = vendor
    sdf = tmp_path / "two_links.sdf"
    mesh = f"<geometry><mesh><uri>package://{PACKAGE}/meshes/base.stl</uri></mesh></geometry>"
    fore = f"<geometry><mesh><uri>package://{PACKAGE}/meshes/fore.stl</uri></mesh></geometry>"
    sdf.write_text(f"""<?xml version="1.0"?>
<sdf version="1.7"><model name="two_links">
  <link name="base"><visual name="v">{mesh}</visual></link>
  <link name="arm"><pose>0 0 0.1 0 0 0</pose><visual name="v">{fore}</visual></link>
  <joint name="weld" type="fixed"><parent>world</parent><child>base</child></joint>
  <joint name="hinge" type="revolute"><parent>base</parent><child>arm</child>
    <axis><xyz>0 1 0</xyz><limit><lower>-1</lower><upper>1</upper></limit></axis></joint>
</model></sdf>""")
    config = _config(vendor, model_file=str(sdf), added_frames={
        "camera_optical": FrameOffset("base", CAMERA.xyz_m, CAMERA.rpy_deg),
        "tool": FrameOffset(parent="arm", xyz_m=[0, 0, 0.3])})
    model = build_tracker_model(config)
    meshes = extract_robot_meshes(model.plant, model.scene_graph)
    expected = sum(len(trimesh.load(package / "meshes" / f"{n}.stl").faces)
                   for n in ("base", "fore"))
    assert meshes.num_triangles == expected
    assert model.robot_joint_names == ["hinge"]


def test_a_missing_mesh_file_is_named(vendor, tmp_path):
    root, package, _ = vendor
    urdf = tmp_path / "broken.urdf"
    urdf.write_text((package / "urdf" / "tiny_arm.urdf").read_text().replace(
        "meshes/hand.dae", "meshes/lost_hand.stl"))
    with pytest.raises(FileNotFoundError, match="lost_hand.stl"):
        build_tracker_model(_config(vendor, model_file=str(urdf)))
