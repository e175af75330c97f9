"""A stock RgbdSensor feeds AddTracker directly: depth encodings, capture times, sequence
numbers, the camera model from Drake's types, and tracking through the whole Diagram."""

import copy

import numpy as np
import pytest
from example_modules import load_example
from pydrake.geometry import ClippingRange, DepthRange, DepthRenderCamera, RenderCameraCore
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource
from pydrake.systems.sensors import CameraInfo, ImageDepth16U, ImageDepth32F

from drake_tracker import AddTracker, DepthImageToFrame, ImageStamper, TrackerParams
from drake_tracker.core.sensors.camera import CameraIntrinsics, as_intrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame, depth_to_metres
from drake_tracker.robot.model import build_tracker_model, robot_preset


def test_depth_encodings_convert_to_metres_with_nan_for_invalid():
    f32 = np.array([[1.5, np.inf], [0.0, np.nan]], np.float32)[:, :, None]
    np.testing.assert_array_equal(depth_to_metres(f32, "32F_m"),
                                  np.array([[1.5, np.nan], [np.nan, np.nan]], np.float32))
    u16 = np.array([[1234, 0], [65535, 1]], np.uint16)[:, :, None]
    out = depth_to_metres(u16, "16U_mm")
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, [[1.234, np.nan], [np.nan, 0.001]], rtol=1e-6)
    with pytest.raises(ValueError, match="unknown encoding"):
        depth_to_metres(u16, "16U")


def test_camera_model_from_drake_types_equals_the_intrinsics():
    info = CameraInfo(320, 240, 300.0, 310.0, 161.0, 118.5)
    expected = CameraIntrinsics(320, 240, 300.0, 310.0, 161.0, 118.5)
    camera = DepthRenderCamera(RenderCameraCore("vtk", info, ClippingRange(0.1, 5.0),
                                                RigidTransform()), DepthRange(0.1, 5.0))
    assert as_intrinsics(info) == expected
    assert as_intrinsics(camera) == expected
    assert as_intrinsics(expected) is expected
    with pytest.raises(TypeError, match="CameraInfo"):
        as_intrinsics("camera")


def test_a_new_capture_time_makes_a_new_frame_even_an_older_one():
    adapter = DepthImageToFrame(encoding="16U_mm", period_s=0.01)
    simulator = Simulator(adapter)
    context = simulator.get_mutable_context()
    image = ImageDepth16U(4, 3)
    image.mutable_data[:] = 1500
    adapter.GetInputPort("depth_image").FixValue(context, image)

    def step(stamp: float):
        adapter.GetInputPort("image_time").FixValue(context, [stamp])
        simulator.AdvanceTo(context.get_time() + 0.01)
        return adapter.GetOutputPort("depth_frame").Eval(context)

    assert step(np.nan).is_empty
    first = step(0.1)
    assert (first.sequence, first.capture_time_s) == (0, 0.1)
    np.testing.assert_allclose(first.depth_m, np.full((3, 4), 1.5, np.float32))
    assert step(0.1).sequence == 0  # the same image seen again
    assert step(0.2).sequence == 1
    # An image stamped before the previous one is passed on (issue 14): the tracker
    # applies it at its capture time inside its buffer's horizon.
    late = step(0.15)
    assert (late.sequence, late.capture_time_s) == (2, 0.15)
    # Only the checks that found a new image changed the state (the others did nothing),
    # and Drake's copies of the state share the stored frame.
    assert simulator.get_num_unrestricted_updates() == 3
    assert copy.deepcopy(late) is late and isinstance(late, DepthFrame)


def test_an_image_port_needs_its_capture_time():
    model = build_tracker_model(robot_preset("apollo"))
    builder = DiagramBuilder()
    readings = builder.AddSystem(ConstantVectorSource(np.zeros(len(model.robot_joint_names))))
    stamp = builder.AddSystem(ConstantVectorSource([0.0]))
    image = builder.AddSystem(ImageStamper(period_s=0.1, model_image=ImageDepth32F(8, 6)))
    with pytest.raises(ValueError, match="image_time"):
        AddTracker(builder, model=model, camera=CameraInfo(8, 6, 0.8), params=TrackerParams(),
                   measured_position=readings.get_output_port(),
                   measurement_time=stamp.get_output_port(), depth=image.GetOutputPort("image"),
                   encoder_period_s=0.001)


@pytest.mark.parametrize("depth", ["32F", "16U"])
def test_stock_rgbd_sensor_tracks_a_biased_robot_ten_times_better_than_encoders(depth):
    example = load_example("track_in_your_diagram.py")
    demo = example.build(depth, duration_s=4.0, seed=3)
    assert demo.tracker.depth_adapter is not None
    errors = example.hand_errors_mm(demo, np.array([1.0, 3.0, 3.5, 4.0]))
    tracker, encoders = errors["tracker"][1:], errors["encoders_only"][1:]
    assert np.median(encoders) > 100.0  # the 8.6 deg bias is there
    assert np.median(tracker) * 10 < np.median(encoders), errors
