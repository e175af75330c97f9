"""Writes the robot models shipped in ``models/`` (run: ``python models/generate_models.py``).

Everything is built from Drake primitives, plus one OBJ mesh this script writes itself, so
nothing is downloaded. The generated files are committed; this script documents how.

* ``apollo.sdf``: an Apollo-like platform. A fixed torso, a 7-DoF arm with KUKA LWR IV
  kinematics (shoulder height 0.31 m, upper arm 0.40 m, forearm 0.39 m, flange 0.078 m,
  limits +-170/120/170/120/170/120/170 deg) with off-axis motor housings on roll links 1,
  3 and 5, a BarrettHand-sized three-finger hand (rigid), and a pan-tilt head carrying
  the depth camera frame ``camera_optical`` (Drake camera convention: +z forward, +x
  right, +y down).
* ``arm6_on_stand.urdf``: a different robot. A 6-DoF arm on a pedestal with a two-finger
  gripper given as an OBJ mesh (``meshes/gripper.obj``), watched by a camera on a fixed stand.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydrake.math import RollPitchYaw, RotationMatrix

HERE = Path(__file__).resolve().parent

ARM_ORANGE = "1.0 0.45 0.05 1"
DARK = "0.2 0.2 0.22 1"
GREY = "0.6 0.6 0.62 1"


def _rpy_from_columns(x_axis, y_axis, z_axis) -> str:
    R = RotationMatrix(np.column_stack([x_axis, y_axis, z_axis]))
    rpy = RollPitchYaw(R).vector()
    return " ".join(f"{v:.9f}" for v in rpy)


def _look_at_rpy(forward, down_hint=(0.0, 0.0, -1.0)) -> str:
    """Camera orientation (x right, y down, z forward) looking along ``forward``."""
    z = np.asarray(forward, float)
    z /= np.linalg.norm(z)
    down = np.asarray(down_hint, float)
    x = np.cross(down, z)  # right = down x forward
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return _rpy_from_columns(x, y, z)


def _inertial(mass: float, inertia: float) -> str:
    return (
        f"<inertial><mass>{mass}</mass><inertia><ixx>{inertia}</ixx><iyy>{inertia}</iyy>"
        f"<izz>{inertia}</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>"
    )


def _visual(name: str, pose: str, geometry: str, rgba: str) -> str:
    return (
        f'<visual name="{name}"><pose>{pose}</pose><geometry>{geometry}</geometry>'
        f"<material><diffuse>{rgba}</diffuse></material></visual>"
    )


def _cyl(radius: float, length: float) -> str:
    return f"<cylinder><radius>{radius}</radius><length>{length}</length></cylinder>"


def _sphere(radius: float) -> str:
    return f"<sphere><radius>{radius}</radius></sphere>"


def _box(x: float, y: float, z: float) -> str:
    return f"<box><size>{x} {y} {z}</size></box>"


def _sdf_link(name: str, pose_relative_to: str, pose: str, body: str, mass=2.0) -> str:
    return (
        f'<link name="{name}"><pose relative_to="{pose_relative_to}">{pose}</pose>'
        f"{_inertial(mass, 0.02)}{body}</link>"
    )


def _sdf_revolute(name, parent, child, axis, lower_deg, upper_deg) -> str:
    return (
        f'<joint name="{name}" type="revolute"><parent>{parent}</parent><child>{child}</child>'
        f"<axis><xyz>{axis}</xyz><limit><lower>{math.radians(lower_deg):.9f}</lower>"
        f"<upper>{math.radians(upper_deg):.9f}</upper><effort>200</effort>"
        f"<velocity>3</velocity></limit></axis></joint>"
    )


def _sdf_fixed(name, parent, child) -> str:
    return (f'<joint name="{name}" type="fixed"><parent>{parent}</parent>'
            f"<child>{child}</child></joint>")


def apollo_sdf() -> str:
    """The Apollo-like platform (see module docstring)."""
    parts = []
    # Torso: fixed to the world. Its origin is on the floor.
    parts.append(
        _sdf_link(
            "torso",
            "__model__",
            "0 0 0 0 0 0",
            _visual("torso_box", "-0.05 0 0.55 0 0 0", _box(0.30, 0.44, 1.10), GREY)
            + _visual("arm_shelf", "0.22 -0.22 0.575 0 0 0", _box(0.16, 0.16, 0.05), GREY)
            + _visual("neck", "0 0 1.2 0 0 0", _cyl(0.05, 0.2), DARK),
            mass=30.0,
        )
    )
    parts.append(_sdf_fixed("torso_weld", "world", "torso"))

    # Arm: KUKA LWR IV kinematics, mounted upright on a shelf in front of the torso.
    # Joint origins along each link's +z; J1 at the base top, J2 0.31 m above the base.
    # (link, parent, offset of this link's joint in the parent, axis, limit, visuals)
    # The links are not bodies of revolution about their own joint axes: like the LWR's,
    # roll links 1, 3 and 5 carry an off-axis motor housing, so a depth image sees their
    # roll angles (a bare cylinder would hide them); the hand shows joint 7's.
    r = 0.06
    arm = [
        ("arm_link_1", "arm_link_0", 0.11, "0 0 1", 170,
         _visual("v", "0 0 0.1 0 0 0", _cyl(r, 0.2), ARM_ORANGE)
         + _visual("housing", "0.05 0 0.12 0 0 0", _box(0.07, 0.08, 0.10), ARM_ORANGE)),
        ("arm_link_2", "arm_link_1", 0.20, "0 1 0", 120,
         _visual("j", "0 0 0 0 0 0", _sphere(r), ARM_ORANGE)
         + _visual("v", "0 0 0.1 0 0 0", _cyl(r, 0.2), ARM_ORANGE)),
        ("arm_link_3", "arm_link_2", 0.20, "0 0 1", 170,
         _visual("v", "0 0 0.1 0 0 0", _cyl(r, 0.2), ARM_ORANGE)
         + _visual("housing", "0 0.05 0.12 0 0 0", _box(0.08, 0.07, 0.10), ARM_ORANGE)),
        ("arm_link_4", "arm_link_3", 0.20, "0 -1 0", 120,
         _visual("j", "0 0 0 0 0 0", _sphere(r), ARM_ORANGE)
         + _visual("v", "0 0 0.1 0 0 0", _cyl(0.055, 0.2), ARM_ORANGE)),
        ("arm_link_5", "arm_link_4", 0.20, "0 0 1", 170,
         _visual("v", "0 0 0.095 0 0 0", _cyl(0.05, 0.19), ARM_ORANGE)
         + _visual("housing", "0.045 0 0.11 0 0 0", _box(0.06, 0.07, 0.09), ARM_ORANGE)),
        ("arm_link_6", "arm_link_5", 0.19, "0 1 0", 120,
         _visual("j", "0 0 0 0 0 0", _sphere(0.055), ARM_ORANGE)),
        ("arm_link_7", "arm_link_6", 0.03, "0 0 1", 170,
         _visual("v", "0 0 0.024 0 0 0", _cyl(0.04, 0.048), DARK)),
    ]
    parts.append(
        _sdf_link(
            "arm_link_0",
            "torso",
            "0.22 -0.22 0.6 0 0 0",
            _visual("v", "0 0 0.055 0 0 0", _cyl(0.07, 0.11), GREY),
            mass=4.0,
        )
    )
    parts.append(_sdf_fixed("arm_base_weld", "torso", "arm_link_0"))
    for i, (link, parent, offset, axis, limit, visuals) in enumerate(arm, start=1):
        parts.append(_sdf_link(link, parent, f"0 0 {offset} 0 0 0", visuals))
        parts.append(_sdf_revolute(f"arm_joint_{i}", parent, link, axis, -limit, limit))

    # Three-finger hand in the BarrettHand's layout and size, rigid, on the flange
    # (0.048 m above joint 7's origin): a rectangular palm, two fingers on one side and
    # the thumb on the other, each finger a proximal and an inward-bent distal link.
    # The layout has no rotational symmetry, so the image sees joint 7.
    hand = _visual("palm", "0 0 0.04 0 0 0", _box(0.09, 0.12, 0.08), DARK)
    for k, (x, y) in enumerate(((0.025, 0.04), (-0.025, 0.04), (0.0, -0.04))):
        bend = 0.5 if y > 0 else -0.5  # distal links lean toward the palm's centre
        hand += _visual(f"finger_{k}_proximal", f"{x} {y} 0.12 0 0 0",
                        _box(0.025, 0.02, 0.08), GREY)
        hand += _visual(f"finger_{k}_distal",
                        f"{x} {y - 0.017 * math.copysign(1, y):.4f} 0.19 {bend} 0 0",
                        _box(0.022, 0.018, 0.07), GREY)
    parts.append(_sdf_link("hand", "arm_link_7", "0 0 0.048 0 0 0", hand, mass=1.0))
    parts.append(_sdf_fixed("hand_weld", "arm_link_7", "hand"))
    parts.append(
        '<frame name="end_effector" attached_to="hand"><pose relative_to="hand">'
        "0 0 0.16 0 0 0</pose></frame>"
    )

    # Pan-tilt head; the camera looks along the tilt link's +x (down for positive tilt).
    parts.append(
        _sdf_link("head_pan_link", "torso", "0 0 1.30 0 0 0",
                  _visual("v", "0 0 0.04 0 0 0", _cyl(0.06, 0.08), DARK), mass=1.0)
    )
    parts.append(_sdf_revolute("head_pan", "torso", "head_pan_link", "0 0 1", -90, 90))
    parts.append(
        _sdf_link("head_tilt_link", "head_pan_link", "0 0 0.12 0 0 0",
                  _visual("skull", "-0.04 0 0.03 0 0 0", _box(0.14, 0.22, 0.14), DARK)
                  + _visual("sensor_bar", "0.045 0 0.0 0 0 0", _box(0.03, 0.18, 0.03), GREY),
                  mass=1.5)
    )
    parts.append(_sdf_revolute("head_tilt", "head_pan_link", "head_tilt_link", "0 1 0", -30, 80))
    cam_rpy = _look_at_rpy([1.0, 0.0, 0.0])
    parts.append(
        '<frame name="camera_optical" attached_to="head_tilt_link">'
        f'<pose relative_to="head_tilt_link">0.08 0 0 {cam_rpy}</pose></frame>'
    )
    body = "\n    ".join(parts)
    return (
        '<?xml version="1.0"?>\n<!-- Generated by models/generate_models.py; do not edit. -->\n'
        f'<sdf version="1.9">\n  <model name="apollo">\n    {body}\n  </model>\n</sdf>\n'
    )


def _box_mesh(center, size):
    """Axis-aligned box as (vertices, normals, faces) with per-face normals."""
    c = np.asarray(center, float)
    h = np.asarray(size, float) / 2.0
    verts, normals, faces = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = [a for a in range(3) if a != axis]
            quad = []
            for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = c.copy()
                p[axis] += sign * h[axis]
                p[u] += su * h[u]
                p[v] += sv * h[v]
                quad.append(p)
            # Counter-clockwise seen from outside.
            if np.dot(np.cross(quad[1] - quad[0], quad[2] - quad[0]), n) < 0:
                quad = quad[::-1]
            base = len(verts)
            verts.extend(quad)
            normals.append(n)
            ni = len(normals)
            faces.append((base, base + 1, base + 2, ni))
            faces.append((base, base + 2, base + 3, ni))
    return verts, normals, faces


def gripper_obj() -> str:
    """A two-finger gripper (palm and two fingers) as one OBJ with normals."""
    lines = ["# Generated by models/generate_models.py: two-finger gripper, metres."]
    all_v, all_n, all_f = [], [], []
    for center, size in (
        ((0, 0, 0.02), (0.05, 0.12, 0.04)),
        ((0, -0.045, 0.085), (0.03, 0.015, 0.09)),
        ((0, 0.045, 0.085), (0.03, 0.015, 0.09)),
    ):
        v, n, f = _box_mesh(center, size)
        vo, no = len(all_v), len(all_n)
        all_v += v
        all_n += n
        all_f += [(a + vo, b + vo, c + vo, ni + no) for a, b, c, ni in f]
    lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in all_v]
    lines += [f"vn {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in all_n]
    lines += [f"f {a + 1}//{n} {b + 1}//{n} {c + 1}//{n}" for a, b, c, n in all_f]
    return "\n".join(lines) + "\n"


def _urdf_link(name, visuals="", mass=2.0) -> str:
    inertial = (
        f'<inertial><mass value="{mass}"/><inertia ixx="0.02" iyy="0.02" izz="0.02" '
        'ixy="0" ixz="0" iyz="0"/></inertial>'
    )
    return f'<link name="{name}">{inertial}{visuals}</link>'


def _material_name(rgba: str) -> str:
    return "rgba_" + rgba.replace(" ", "_").replace(".", "p")


def _urdf_visual(xyz, rpy, geometry, rgba) -> str:
    return (
        f'<visual><origin xyz="{xyz}" rpy="{rpy}"/><geometry>{geometry}</geometry>'
        f'<material name="{_material_name(rgba)}"><color rgba="{rgba}"/></material></visual>'
    )


def arm6_urdf() -> str:
    """The second robot: a 6-DoF arm on a pedestal and a camera on a fixed stand."""
    blue = "0.2 0.4 0.8 1"
    links = [_urdf_link("pedestal", _urdf_visual("0 0 0.25", "0 0 0",
                                                 '<box size="0.25 0.25 0.5"/>', GREY), 10.0)]
    joints = ['<joint name="pedestal_weld" type="fixed"><parent link="world"/>'
              '<child link="pedestal"/><origin xyz="0 0 0"/></joint>']
    spec = [
        # (joint, parent, child, origin xyz, axis, limit deg, visual)
        ("shoulder_pan", "pedestal", "link_1", "0 0 0.5", "0 0 1", 170,
         _urdf_visual("0 0 0.05", "0 0 0", '<cylinder radius="0.06" length="0.1"/>', blue)),
        ("shoulder_lift", "link_1", "link_2", "0 0 0.1", "0 1 0", 120,
         _urdf_visual("0 0 0.21", "0 0 0", '<cylinder radius="0.05" length="0.42"/>', blue)),
        ("elbow", "link_2", "link_3", "0 0 0.42", "0 1 0", 150,
         _urdf_visual("0 0 0.195", "0 0 0", '<cylinder radius="0.045" length="0.39"/>', blue)),
        ("wrist_1", "link_3", "link_4", "0 0 0.39", "0 1 0", 170,
         _urdf_visual("0 0 0.045", "0 0 0", '<sphere radius="0.045"/>', DARK)),
        ("wrist_2", "link_4", "link_5", "0 0 0.09", "0 0 1", 170,
         _urdf_visual("0 0 0.04", "0 0 0", '<cylinder radius="0.04" length="0.08"/>', blue)),
        ("wrist_3", "link_5", "link_6", "0 0 0.08", "0 1 0", 170,
         _urdf_visual("0 0 0.01", "0 0 0", '<cylinder radius="0.04" length="0.02"/>', DARK)),
    ]
    for joint, parent, child, xyz, axis, lim, vis in spec:
        links.append(_urdf_link(child, vis))
        joints.append(
            f'<joint name="{joint}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="{axis}"/>'
            f'<limit lower="{-math.radians(lim):.9f}" upper="{math.radians(lim):.9f}" '
            'effort="150" velocity="3"/></joint>'
        )
    links.append(_urdf_link("gripper", _urdf_visual(
        "0 0 0", "0 0 0", '<mesh filename="meshes/gripper.obj"/>', GREY), 0.5))
    joints.append('<joint name="gripper_weld" type="fixed"><parent link="link_6"/>'
                  '<child link="gripper"/><origin xyz="0 0 0.02"/></joint>')
    links.append(_urdf_link("tool_center", "", 0.01))
    joints.append('<joint name="tool_center_weld" type="fixed"><parent link="gripper"/>'
                  '<child link="tool_center"/><origin xyz="0 0 0.12"/></joint>')
    # Camera stand: in front of the arm, looking back at it and down.
    links.append(_urdf_link("camera_stand", _urdf_visual(
        "0 0 -0.7", "0 0 0", '<cylinder radius="0.03" length="1.4"/>', DARK), 5.0))
    joints.append('<joint name="camera_stand_weld" type="fixed"><parent link="world"/>'
                  '<child link="camera_stand"/><origin xyz="1.5 0.2 1.4"/></joint>')
    forward = np.array([-1.0, -0.15, -0.55])
    rpy = _look_at_rpy(forward)
    links.append(_urdf_link("camera_optical", "", 0.01))
    joints.append('<joint name="camera_optical_weld" type="fixed"><parent link="camera_stand"/>'
                  f'<child link="camera_optical"/><origin xyz="0 0 0.05" rpy="{rpy}"/></joint>')
    body = "\n  ".join(links + joints)
    return (
        '<?xml version="1.0"?>\n<!-- Generated by models/generate_models.py; do not edit. -->\n'
        f'<robot name="arm6">\n  {body}\n</robot>\n'
    )


def main() -> None:
    (HERE / "apollo.sdf").write_text(apollo_sdf())
    (HERE / "meshes").mkdir(exist_ok=True)
    (HERE / "meshes" / "gripper.obj").write_text(gripper_obj())
    (HERE / "arm6_on_stand.urdf").write_text(arm6_urdf())


if __name__ == "__main__":
    main()
