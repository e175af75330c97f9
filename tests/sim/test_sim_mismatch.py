"""The world is not the model: the world robot's hand is off the nominal forward kinematics
by millimetres, its cable and larger hand are in the images but not in the model, the
recording keeps the nominal robot, and a seed gives one world."""

import dataclasses

import numpy as np
import pytest
from pydrake.common.yaml import yaml_dump
from pydrake.geometry import SceneGraph

from drake_tracker.robot.model import build_tracker_model
from drake_tracker.sim.depth_camera import depth_render_camera, ensure_vtk_renderer
from drake_tracker.sim.record import simulate_and_record
from drake_tracker.sim.scenario.load import ModelMismatchConfig, Scenario, load_scenario
from drake_tracker.sim.world import build_simulated_world


def small(mismatch: ModelMismatchConfig | None, name: str = "s-full-arm/none") -> Scenario:
    s = load_scenario(name)
    s.camera.width, s.camera.height = 160, 120
    s.encoders.rate_hz = 100.0
    s.environment = False
    # Drake's own shapes, so that the world without a mismatch renders exactly as the
    # model (the default meshes are within 0.3 mm: tests/sim/test_curved_shapes.py)
    s.camera.curved_surface_tolerance_m = 0.0
    if mismatch is not None:
        s.model_mismatch = mismatch
    return s


def world_outputs(scenario: Scenario, t: float):
    """(true joint angles, true camera offset, true X_CE, noise-free depth render) at t."""
    diagram, world = build_simulated_world(scenario)
    context = diagram.CreateDefaultContext()
    context.SetTime(t)
    sensor = diagram.GetSubsystemByName("world_depth_camera_rgbd")
    image = sensor.depth_image_32F_output_port().Eval(sensor.GetMyContextFromRoot(context))
    depth = np.array(image.data[:, :, 0], float)
    depth[~np.isfinite(depth)] = np.nan
    return (diagram.GetOutputPort("true_position").Eval(context),
            diagram.GetOutputPort("true_camera_offset").Eval(context),
            diagram.GetOutputPort("true_X_CE").Eval(context), depth, world)


def nominal_model_view(scenario: Scenario, q: np.ndarray, offset: np.ndarray):
    """The tracker's (nominal) model at joint angles q and camera offset: its X_CE and its
    depth render from its own camera frame (an independent scene)."""
    model = build_tracker_model(scenario.resolved_robot_config())
    ensure_vtk_renderer(model.scene_graph)
    context = model.diagram.CreateDefaultContext()
    plant_context = model.plant.GetMyMutableContextFromRoot(context)
    positions = np.zeros(model.plant.num_positions())
    names = model.joint_names
    for name, value in zip(model.robot_joint_names, q):
        positions[names.index(name)] = value
    positions[model.virtual_joint_indices] = offset
    model.plant.SetPositions(plant_context, positions)
    X_CE = model.plant.CalcRelativeTransform(plant_context, model.camera_frame,
                                             model.end_effector_frame)
    X_WC = model.camera_frame.CalcPoseInWorld(plant_context)
    query = model.scene_graph.get_query_output_port().Eval(
        model.scene_graph.GetMyContextFromRoot(context))
    image = query.RenderDepthImage(depth_render_camera(scenario.camera),
                                   SceneGraph.world_frame_id(), X_WC)
    depth = np.array(image.data[:, :, 0], float)
    depth[~np.isfinite(depth)] = np.nan
    return X_CE, depth


JOINTS_ONLY = ModelMismatchConfig(joint_origin_mm=3.0, joint_origin_deg=0.3, seed=4)
GEOMETRY_ONLY = ModelMismatchConfig(cable=True, hand_scale=1.15)


def test_world_hand_is_millimetres_off_the_nominal_forward_kinematics():
    for t in (0.0, 2.0):
        q, offset, X_CE, _, _ = world_outputs(small(JOINTS_ONLY), t)
        X_model, _ = nominal_model_view(small(None), q, offset)
        error_mm = 1e3 * np.linalg.norm(X_CE.translation() - X_model.translation())
        assert 2.0 < error_mm < 40.0, (t, error_mm)
        # Without a mismatch the world's truth IS the model's forward kinematics.
        q0, offset0, X0, _, _ = world_outputs(small(None), t)
        np.testing.assert_allclose(q0, q, atol=0)  # same joint angles either way
        X_model0, _ = nominal_model_view(small(None), q0, offset0)
        np.testing.assert_allclose(X0.GetAsMatrix4(), X_model0.GetAsMatrix4(), atol=1e-12)


def test_cable_and_larger_hand_are_seen_but_not_in_the_model():
    q, offset, _, depth, _ = world_outputs(small(GEOMETRY_ONLY), 1.0)
    _, model_depth = nominal_model_view(small(None), q, offset)
    _, _, _, plain_depth, _ = world_outputs(small(None), 1.0)
    with np.errstate(invalid="ignore"):
        # The model renders exactly as the world without extra geometry.
        assert np.nanmax(np.abs(model_depth - plain_depth)) < 1e-4
        nearer = (depth < model_depth - 0.003) | (np.isfinite(depth) & np.isnan(model_depth))
        farther = depth > model_depth + 0.003
    # Geometry was only added: pixels only come nearer, and enough of them to matter.
    assert farther.sum() == 0
    assert nearer.sum() >= 300  # measured 850 of 2967 robot pixels
    # Each part on its own shows up too.
    for part in (ModelMismatchConfig(cable=True), ModelMismatchConfig(hand_scale=1.15)):
        _, _, _, part_depth, _ = world_outputs(small(part), 1.0)
        with np.errstate(invalid="ignore"):
            changed = (part_depth < model_depth - 0.003) | (
                np.isfinite(part_depth) & np.isnan(model_depth))
        assert changed.sum() >= 150, part  # measured: cable 578, hand 305


def test_the_recorded_run_keeps_the_nominal_robot_and_the_encoders_read_the_world():
    s = small(dataclasses.replace(JOINTS_ONLY, cable=True, hand_scale=1.15))
    s.encoders.noise_sigma_deg = 0.0
    run = simulate_and_record(s, duration_s=0.2, image_stride=8)
    assert run.robot_config_yaml == yaml_dump(dataclasses.asdict(s.resolved_robot_config()))
    assert "world_origin" not in run.robot_config_yaml
    # The encoders read the world robot's joint angles (bias none, noise off).
    truth_at_readings = run.truth_positions_rad[np.searchsorted(run.truth_times_s,
                                                                run.reading_times_s)]
    np.testing.assert_allclose(run.readings_rad, truth_at_readings, atol=1e-12)
    # The truth is the world robot's: off the nominal model's forward kinematics.
    X_model, _ = nominal_model_view(small(None), run.truth_positions_rad[-1],
                                    run.truth_camera_offset[-1])
    assert np.linalg.norm(run.truth_X_CE[-1][:3, 3] - X_model.translation()) > 0.002


def test_same_seed_same_world_and_another_seed_another():
    def hand(seed: int):
        config = dataclasses.replace(JOINTS_ONLY, seed=seed)
        return world_outputs(small(config), 1.0)[2].GetAsMatrix4()

    np.testing.assert_array_equal(hand(4), hand(4))
    assert np.abs(hand(4) - hand(5)).max() > 1e-4


def test_mismatch_preset_and_bad_values():
    s = load_scenario("s-full-arm-mismatch/constant")
    assert s.model_mismatch.enabled and s.model_mismatch.joint_origin_mm == 3.0
    assert s.resolved_robot_config().model_file == "apollo.sdf"
    assert load_scenario("arm++-mismatch/none").model_mismatch.cable
    assert not load_scenario("s-full-arm/constant").model_mismatch.enabled
    s.model_mismatch.hand_scale = 0.0
    with pytest.raises(ValueError, match=r"model_mismatch\.hand_scale"):
        from drake_tracker.sim.scenario.load import validate_scenario

        validate_scenario(s, check_model=False)
    s = load_scenario("static/none")
    s.model_mismatch.joints = ["no_such_joint"]
    with pytest.raises(ValueError, match=r"model_mismatch\.joints"):
        from drake_tracker.sim.scenario.load import validate_scenario

        validate_scenario(s)
