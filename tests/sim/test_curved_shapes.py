"""The simulated camera's curved shapes as meshes (sim/curved_shapes.py): within the
stated distance of the true surfaces, and rendered by RenderEngineVtk like Drake's own
shapes."""

import numpy as np
import pytest
from pydrake.geometry import (
    Capsule,
    ClippingRange,
    Cylinder,
    DepthRange,
    DepthRenderCamera,
    Ellipsoid,
    MakeRenderEngineVtk,
    Mesh,
    RenderCameraCore,
    RenderEngineVtkParams,
    Role,
    Sphere,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import SpatialInertia
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraInfo

from drake_tracker.core.render.meshes import tessellate_shape
from drake_tracker.sim.curved_shapes import (
    segments_for,
    sphere_deviation,
    tessellate_curved_perception,
)

TOLERANCE_M = 0.0003


def _random_surface_points(vertices, triangles, rng, per_triangle=20):
    """Points drawn uniformly on every triangle (seeded)."""
    u = rng.random((len(triangles), per_triangle, 2))
    flip = u.sum(axis=2) > 1.0
    u[flip] = 1.0 - u[flip]
    a, b, c = (vertices[triangles[:, k]][:, None, :] for k in range(3))
    return (a + u[..., :1] * (b - a) + u[..., 1:] * (c - a)).reshape(-1, 3)


def _distance_to_surface(shape, p):
    """Unsigned distance of points p (N, 3) from the true surface of ``shape``."""
    if isinstance(shape, Sphere):
        return np.abs(np.linalg.norm(p, axis=1) - shape.radius())
    h = 0.5 * shape.length()
    radial = np.linalg.norm(p[:, :2], axis=1)
    if isinstance(shape, Capsule):  # distance to the axis segment, minus the radius
        nearest = np.clip(p[:, 2], -h, h)
        return np.abs(np.hypot(radial, p[:, 2] - nearest) - shape.radius())
    # cylinder: the nearer of the side and the caps, for points near the surface
    side = np.abs(radial - shape.radius())
    cap = np.abs(np.abs(p[:, 2]) - h)
    return np.where(np.abs(p[:, 2]) < h - 1e-9, np.minimum(side, np.where(
        radial < shape.radius(), cap, np.inf)), np.where(radial <= shape.radius() + 1e-9,
                                                        cap, np.hypot(side, cap)))


@pytest.mark.parametrize("shape", [Sphere(0.06), Sphere(0.09), Cylinder(0.05, 0.2),
                                   Capsule(0.04, 0.1)])
def test_the_meshes_stay_within_the_tolerance_and_use_the_fewest_segments(shape):
    rng = np.random.default_rng(5)
    segments = segments_for(shape, TOLERANCE_M)
    v, t = tessellate_shape(shape, segments)
    worst = _distance_to_surface(shape, _random_surface_points(v, t, rng)).max()
    assert worst <= TOLERANCE_M
    if isinstance(shape, Sphere) and segments > 8:  # one step fewer would not do
        v, t = tessellate_shape(shape, segments - 4)
        coarser = _distance_to_surface(shape, _random_surface_points(v, t, rng)).max()
        assert coarser > TOLERANCE_M
        assert sphere_deviation(segments - 4) * shape.radius() > TOLERANCE_M
    # the sphere is the worst kind: the others' deviation is no larger than its own
    # (sphere_deviation samples a grid on each triangle: 1 % for what falls between)
    assert worst <= 1.01 * sphere_deviation(segments) * shape.radius()


def test_ellipsoid_meshes_stay_within_the_tolerance():
    shape = Ellipsoid(0.08, 0.05, 0.03)
    v, t = tessellate_shape(shape, segments_for(shape, TOLERANCE_M))
    p = _random_surface_points(v, t, np.random.default_rng(6))
    # distance along the ray from the centre to the true surface: no smaller than the
    # distance to the surface, so a bound on it bounds the deviation
    along_ray = np.abs(1.0 - 1.0 / np.linalg.norm(p / [0.08, 0.05, 0.03], axis=1))
    assert (along_ray * np.linalg.norm(p, axis=1)).max() <= TOLERANCE_M * 1.05


def _scene(tolerance_m):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    scene_graph.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams()))
    body = plant.AddRigidBody("body", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1))
    shapes = {"sphere": (Sphere(0.06), [-0.15, -0.08, 0.0]),
              "cylinder": (Cylinder(0.05, 0.2), [0.0, -0.08, 0.0]),
              "capsule": (Capsule(0.04, 0.1), [0.15, -0.08, 0.0]),
              "ellipsoid": (Ellipsoid(0.08, 0.05, 0.03), [-0.1, 0.1, 0.0])}
    for name, (shape, xyz) in shapes.items():
        X = RigidTransform(RollPitchYaw(0.4, 0.3, 0.0), xyz)
        plant.RegisterVisualGeometry(body, X, shape, name, np.array([1.0, 0.5, 0.2, 1.0]))
    plant.RegisterVisualGeometry(plant.world_body(), RigidTransform([0.12, 0.1, 0.0]),
                                 Sphere(0.05), "anchored", np.array([1.0, 1.0, 1.0, 1.0]))
    plant.Finalize()
    replaced = tessellate_curved_perception(scene_graph, tolerance_m)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    X_WB = RigidTransform(RollPitchYaw(0.2, -0.1, 0.3), [0.01, 0.0, 0.02])
    plant.SetFreeBodyPose(plant.GetMyMutableContextFromRoot(context), body, X_WB)
    return scene_graph, scene_graph.GetMyContextFromRoot(context), replaced


def _depth(scene_graph, scene_context, width=160, height=120):
    camera = DepthRenderCamera(
        RenderCameraCore("vtk", CameraInfo(width, height, np.radians(40.0)),
                         ClippingRange(0.05, 3.0), RigidTransform()),
        DepthRange(0.05, 3.0))
    X_WC = RigidTransform(RollPitchYaw(np.pi, 0.0, 0.0), [0.0, 0.0, 0.55])  # looks down -z
    query = scene_graph.get_query_output_port().Eval(scene_context)
    image = query.RenderDepthImage(camera, scene_graph.world_frame_id(), X_WC)
    return np.array(image.data)[:, :, 0]


def test_the_camera_renders_the_meshes_like_drakes_own_shapes():
    drakes, drakes_context, none = _scene(0.0)
    meshes, meshes_context, replaced = _scene(TOLERANCE_M)
    assert none == 0 and replaced == 5
    inspector = meshes.model_inspector()
    seen = inspector.GetAllGeometryIds(Role.kPerception)
    assert len(seen) == 5
    assert all(isinstance(inspector.GetShape(g), Mesh) for g in seen)
    # Meshcat and other illustration still see the true shapes
    drawn = inspector.GetAllGeometryIds(Role.kIllustration)
    assert sorted(type(inspector.GetShape(g)).__name__ for g in drawn) == [
        "Capsule", "Cylinder", "Ellipsoid", "Sphere", "Sphere"]
    a, b = _depth(drakes, drakes_context), _depth(meshes, meshes_context)
    hit_a, hit_b = np.isfinite(a), np.isfinite(b)
    assert hit_a.sum() > 2000  # the shapes fill a good part of the image
    assert (hit_a == hit_b).sum() >= hit_a.size - 0.01 * (hit_a | hit_b).sum()
    both = hit_a & hit_b
    shared = np.abs(a[both] - b[both])
    assert np.median(shared) <= TOLERANCE_M
    assert np.percentile(shared, 95) <= 2 * TOLERANCE_M + 1e-4


def test_a_shape_too_large_for_the_tolerance_keeps_drakes_own():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    plant.RegisterVisualGeometry(plant.world_body(), RigidTransform(), Sphere(0.5), "big",
                                 np.array([1.0, 1.0, 1.0, 1.0]))
    plant.RegisterVisualGeometry(plant.world_body(), RigidTransform([2.0, 0.0, 0.0]),
                                 Sphere(0.05), "small", np.array([1.0, 1.0, 1.0, 1.0]))
    plant.Finalize()
    assert tessellate_curved_perception(scene_graph, TOLERANCE_M) == 1
    inspector = scene_graph.model_inspector()
    kept = {inspector.GetName(g): type(inspector.GetShape(g)).__name__
            for g in inspector.GetAllGeometryIds(Role.kPerception)}
    assert kept == {"big": "Sphere", "small_tessellated": "Mesh"}
    with pytest.raises(ValueError, match="needs more than 48 segments"):
        segments_for(Sphere(0.5), TOLERANCE_M)


def test_a_negative_tolerance_is_an_error():
    scene_graph = _scene(0.0)[0]
    with pytest.raises(ValueError, match="tolerance_m must be >= 0"):
        tessellate_curved_perception(scene_graph, -1e-4)
    with pytest.raises(ValueError, match="tolerance_m must be > 0"):
        segments_for(Sphere(0.1), 0.0)
