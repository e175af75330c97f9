"""The demo with two cameras (issue 46): every camera of the scenario is wired into the
tracker, and Meshcat shows each camera's frustum at its true and at its estimated pose,
named by the camera, and each camera's points; each estimated pose is the one Drake's
kinematics gives the estimate."""

import contextlib
import io
import json

import numpy as np
from test_demo import meshcat_materials

from drake_tracker.cli.main import main
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model
from drake_tracker.sim.scenario.load import load_scenario
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem

SCENARIO = "occlusion-lasting-2cam/constant"


def test_the_demo_shows_each_camera_at_its_true_and_estimated_pose(tmp_path):
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["demo", "--scenario", SCENARIO, "--duration", "0.6",
                     "--out", str(tmp_path)])
    assert code == 0, stderr.getvalue()[-2000:]
    materials = meshcat_materials((tmp_path / "meshcat.html").read_text())
    views = {"/drake/true_camera", "/drake/estimated_camera", "/drake/true_post_camera",
             "/drake/estimated_post_camera", "/drake/camera_points",
             "/drake/post_camera_points", "/drake/estimate", "/drake/encoders_only"}
    assert views <= set(materials), sorted(materials)
    graph = (tmp_path / "diagram.dot").read_text()
    assert "post_camera_depth_frame" in graph and "camera_depth_frame" in graph
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["image_updates_late"] + report["image_updates_on_time"] >= 2


def test_each_camera_s_estimated_pose_is_drake_s_kinematics_of_the_estimate():
    """The bank's ``<name>_X_WC`` (what the frustum shows) against Drake's
    ``Frame.CalcPoseInWorld`` at the belief's mean angles, random but seeded."""
    model = build_tracker_model(load_scenario(SCENARIO).resolved_robot_config())
    assert model.camera_names == ["camera", "post_camera"]
    bank = JointKalmanBankSystem(model=model, params=TrackerParams(), period_s=0.001)
    context = bank.CreateDefaultContext()
    rng = np.random.default_rng(46)
    belief = np.zeros((5, model.num_joints))
    belief[0] = rng.uniform(-0.3, 0.3, model.num_joints)
    context.get_mutable_discrete_state().set_value(0, belief.ravel())
    plant_context = model.plant.CreateDefaultContext()
    model.plant.SetPositions(plant_context, belief[0])
    poses = []
    for camera in model.cameras:
        X_WC = bank.GetOutputPort(f"{camera.name}_X_WC").Eval(context)
        expected = camera.frame.CalcPoseInWorld(plant_context)
        np.testing.assert_allclose(X_WC.GetAsMatrix4(), expected.GetAsMatrix4(), atol=1e-9)
        offset = bank.GetOutputPort(f"{camera.name}_camera_offset").Eval(context)
        np.testing.assert_array_equal(offset, belief[0, model.camera_joint_indices(camera.name)])
        poses.append(X_WC.translation())
    assert np.linalg.norm(poses[0] - poses[1]) > 0.5  # two cameras, not one drawn twice
