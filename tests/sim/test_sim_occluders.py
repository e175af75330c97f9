"""Occluders: each shape, attachment and path puts the object where its formula says, only
inside its window; the heavy-occlusion presets hide most of the arm; YAML and errors."""

import numpy as np
import pytest

from drake_tracker.sim.scenario.load import OccluderSpec, Scenario, load_scenario
from drake_tracker.sim.world import build_simulated_world


def small(name: str, occluders: list[OccluderSpec]) -> Scenario:
    s = load_scenario(name)
    s.camera.width, s.camera.height = 160, 120
    s.environment = False
    s.occluders = occluders
    return s


class Scene:
    """Noise-free renders of a scenario's world, the true camera pose and FK, at any t."""

    def __init__(self, scenario: Scenario):
        self.diagram, self.world = build_simulated_world(scenario)
        self.sensor = self.diagram.GetSubsystemByName("world_depth_camera_rgbd")
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = self.world.plant.CreateDefaultContext()

    def render(self, t: float) -> np.ndarray:
        self.context.SetTime(t)
        port = self.sensor.depth_image_32F_output_port()
        image = np.array(port.Eval(self.sensor.GetMyContextFromRoot(self.context)).data[:, :, 0])
        return np.where(np.isfinite(image), image, np.nan)

    def in_camera(self, t: float, p_W: np.ndarray) -> np.ndarray:
        """``p_W`` in the true camera frame at ``t`` (independent FK on the world plant)."""
        self.world.plant.SetPositions(self.plant_context, self.world.reference.positions(t))
        X_WC = self.world.camera_frame.CalcPoseInWorld(self.plant_context)
        return X_WC.inverse() @ np.asarray(p_W, float)

    def frame_pose(self, t: float, name: str):
        self.world.plant.SetPositions(self.plant_context, self.world.reference.positions(t))
        return self.world.plant.GetFrameByName(name).CalcPoseInWorld(self.plant_context)

    def pixel(self, p_C: np.ndarray) -> tuple[int, int]:
        f = self.world.intrinsics
        x, y, z = p_C
        return int(round(f.fy * y / z + f.cy)), int(round(f.fx * x / z + f.cx))


# A point 0.6 m along the camera's optical axis at Apollo's home pose (head fixed in
# s-full-arm): camera at (0.091, -0.02, 1.381) looking along (0.871, 0.026, -0.49).
AHEAD = [0.614, -0.004, 1.087]
WINDOWS = [(0.0, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 4.0)]


@pytest.fixture(scope="module")
def scenes():
    occluders = [
        OccluderSpec(shape="sphere", size_m=[0.05], motion="world", xyz_m=AHEAD,
                     enter_s=0.0, leave_s=1.0),
        OccluderSpec(shape="cylinder", size_m=[0.04, 0.1], motion="frame", frame="hand",
                     xyz_m=[0.0, 0.0, 0.3], enter_s=1.0, leave_s=2.0),
        OccluderSpec(shape="box", size_m=[0.1, 0.1, 0.04], motion="frame", frame="camera",
                     xyz_m=[0.02, -0.03, 0.5], enter_s=2.0, leave_s=3.0),
        OccluderSpec(shape="sphere", size_m=[0.04], motion="path",
                     waypoint_times_s=[3.0, 4.0],
                     waypoints_m=[[0.42, 0.08, 1.2], [0.46, -0.08, 1.17]],
                     enter_s=3.0, leave_s=4.0),
    ]
    return Scene(small("s-full-arm/none", occluders)), Scene(small("s-full-arm/none", []))


def test_sphere_fixed_in_the_world_is_where_it_was_put(scenes):
    scene, clear = scenes
    p_C = scene.in_camera(0.5, AHEAD)
    v, u = scene.pixel(p_C)
    expected = p_C[2] * (1.0 - 0.05 / np.linalg.norm(p_C))  # front of the sphere on the ray
    assert scene.render(0.5)[v, u] == pytest.approx(expected, abs=0.004)


def test_cylinder_attached_to_the_hand_moves_with_it(scenes):
    scene, _ = scenes
    for t in (1.2, 1.8):  # the arm moves between the two times
        p_W = scene.frame_pose(t, "hand") @ np.array([0.0, 0.0, 0.3])
        p_C = scene.in_camera(t, p_W)
        v, u = scene.pixel(p_C)
        depth = scene.render(t)[v, u]
        # The nearest surface of a 4 cm x 10 cm cylinder around its centre's ray.
        assert p_C[2] - 0.06 < depth < p_C[2] + 0.001


def test_box_attached_to_the_camera_sits_at_its_offset(scenes):
    scene, _ = scenes
    image = scene.render(2.5)
    v, u = scene.pixel(np.array([0.02, -0.03, 0.5]))
    assert image[v, u] == pytest.approx(0.5 - 0.02, abs=1e-4)  # the face 2 cm before the centre
    # Its edges: 10 cm wide at 0.48 m, as the camera model projects them.
    f = scene.world.intrinsics
    covered = np.isclose(image, 0.48, atol=1e-3)
    assert covered.sum() == pytest.approx((f.fx * 0.1 / 0.48) * (f.fy * 0.1 / 0.48), rel=0.1)


def test_sphere_on_a_path_is_between_its_waypoints(scenes):
    scene, _ = scenes
    for t, fraction in ((3.25, 0.25), (3.75, 0.75)):
        start, end = np.array([0.42, 0.08, 1.2]), np.array([0.46, -0.08, 1.17])
        p_W = (1 - fraction) * start + fraction * end
        p_C = scene.in_camera(t, p_W)
        v, u = scene.pixel(p_C)
        expected = p_C[2] * (1.0 - 0.04 / np.linalg.norm(p_C))
        assert scene.render(t)[v, u] == pytest.approx(expected, abs=0.004)


def test_each_occluder_is_absent_outside_its_window(scenes):
    scene, clear = scenes
    for t in (4.5, 6.0):  # after every window
        np.testing.assert_array_equal(scene.render(t), clear.render(t))
    for k, (enter, leave) in enumerate(WINDOWS):
        t = 0.5 * (enter + leave)
        changed = ~np.isclose(scene.render(t), clear.render(t), equal_nan=True)
        assert changed.sum() > 20, k  # exactly one occluder in view: the one in its window


def robot_hidden_fraction(with_occluder: np.ndarray, clear: np.ndarray) -> float:
    robot = np.isfinite(clear)
    with np.errstate(invalid="ignore"):
        return float(np.mean(with_occluder[robot] < clear[robot] - 0.01))


@pytest.mark.parametrize("name", ["occlusion-heavy/constant", "occlusion-lasting/constant"])
def test_heavy_occlusion_hides_most_of_the_arm_in_its_window(name):
    s = small(name, [])
    s.occluders = load_scenario(name).occluders
    scene, clear = Scene(s), Scene(small(name, []))
    o = s.occluders[0]
    assert o.enter_s == pytest.approx(7.5)
    in_window = [8.0, 12.0, 16.0, 20.0, 22.0] + ([26.0, 29.9] if o.leave_s > 30 else [])
    for t in in_window:
        assert robot_hidden_fraction(scene.render(t), clear.render(t)) >= 0.6, t
    after = [] if o.leave_s > 30 else [23.0, 27.0]
    assert o.leave_s == (np.inf if "lasting" in name else pytest.approx(22.5))
    for t in [0.0, 7.0] + after:
        np.testing.assert_array_equal(scene.render(t), clear.render(t))


def test_legacy_occluder_is_the_first_of_the_list():
    s = load_scenario("occlusion/none")
    from drake_tracker.sim.scenario.load import scenario_occluders

    (box,) = scenario_occluders(s)
    assert (box.motion, box.shape, box.enter_s, box.leave_s, box.ramp_s) == (
        "line-sweep", "box", 8.0, 52.0, 2.0)
    s.occluders = [OccluderSpec(shape="sphere", size_m=[0.1])]
    assert [o.shape for o in scenario_occluders(s)] == ["box", "sphere"]


def test_occluders_load_from_yaml_and_errors_name_the_field(tmp_path):
    path = tmp_path / "occ.yaml"
    path.write_text(
        "preset: s-full-arm/constant\n"
        "occluders:\n"
        "  - {shape: cylinder, size_m: [0.05, 0.3], motion: frame, frame: camera,\n"
        "     xyz_m: [0, 0, 0.4], enter_s: 2.0, leave_s: .inf}\n"
        "  - {shape: sphere, size_m: [0.1], motion: path, waypoint_times_s: [0, 5],\n"
        "     waypoints_m: [[0.5, 0, 1], [0.6, 0.2, 1]]}\n")
    s = load_scenario(path)
    assert [o.shape for o in s.occluders] == ["cylinder", "sphere"]
    assert s.occluders[0].leave_s == np.inf and s.occluders[1].waypoints_m[1] == [0.6, 0.2, 1]
    bad = {
        "occluders[0].size_m": "  - {shape: sphere, size_m: [0.1, 0.2]}\n",
        "occluders[0].shape": "  - {shape: cone}\n",
        "occluders[0].frame": "  - {motion: frame, frame: no_such_link}\n",
        "occluders[0].leave_s": "  - {enter_s: 5.0, leave_s: 2.0}\n",
        "occluders[0].waypoints_m": "  - {motion: path, waypoint_times_s: [0, 1],\n"
                                    "     waypoints_m: [[0, 0, 1]]}\n",
    }
    for field, entry in bad.items():
        path.write_text("preset: static/none\noccluders:\n" + entry)
        with pytest.raises(ValueError, match=field.replace(".", r"\.").replace("[", r"\[")):
            load_scenario(path)


def test_a_shortened_run_keeps_every_event_in_it():
    from drake_tracker.sim.scenario.timing import shorten_scenario

    heavy = shorten_scenario(load_scenario("occlusion-heavy/ramp"), 10.0)
    o = heavy.occluders[0]
    assert (heavy.duration_s, o.enter_s, o.leave_s) == (10.0, 2.5, 7.5)
    assert heavy.encoders.ramp_duration_s == pytest.approx(10.0 / 3)
    assert shorten_scenario(load_scenario("occlusion-lasting/none"), 10.0).occluders[0].leave_s \
        == np.inf
    # The legacy events: as the evaluation compressed them before.
    legacy = shorten_scenario(load_scenario("occlusion/time-varying"), 10.0)
    assert (legacy.occluder.start_s, legacy.occluder.end_s) == (2.5, 8.5)
    assert (legacy.encoders.step_period_s, legacy.encoders.step_transition_s) == (3.0, 1.0)
    out = shorten_scenario(load_scenario("in-out-in/none"), 10.0).trajectory
    assert (out.excursion_start_s, out.excursion_ramp_s, out.excursion_duration_s) == (
        2.0, 1.0, 4.0)
    assert shorten_scenario(load_scenario("static/none"), 60.0).duration_s == 30.0
