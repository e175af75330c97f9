"""RecordedRunSource shows, at any time t (forwards, backwards, repeated), the latest
reading stamped at or before t and the latest image arrived by t, as a direct lookup
in the recording says; each image is one DepthFrame however often it is shown."""

import numpy as np
import pytest

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.io.recording import RecordedRun
from drake_tracker.systems.recorded_run_source import RecordedRunSource


@pytest.fixture(scope="module")
def run():
    rng = np.random.default_rng(3)
    reading_times = np.cumsum(rng.uniform(0.0005, 0.0015, 400))
    captures = np.array([0.02, 0.05, 0.08, 0.11, 0.14])
    arrivals = captures + np.array([0.03, 0.09, 0.02, 0.05, 0.01])  # out of order
    images = rng.uniform(0.5, 2.0, (5, 6, 8)).astype(np.float32)
    return RecordedRun(
        robot_config_yaml="", joint_names=["a", "b", "c"],
        reading_times_s=reading_times, readings_rad=rng.normal(size=(400, 3)),
        image_capture_times_s=captures, image_arrival_times_s=arrivals,
        depth_images_m=images, camera_intrinsics=CameraIntrinsics.from_fov(
            8, 6, np.radians(45.0)),
        truth_times_s=np.zeros(0), truth_positions_rad=np.zeros((0, 3)),
        truth_bias_rad=np.zeros((0, 3)), truth_camera_offset=np.zeros((0, 6)),
        truth_X_CE=np.zeros((0, 4, 4)))


def test_the_source_shows_what_a_direct_lookup_in_the_recording_says(run):
    source = RecordedRunSource(run)
    context = source.CreateDefaultContext()
    rng = np.random.default_rng(4)
    forwards = np.arange(0.0, 0.45, 0.001)
    times = np.concatenate([forwards, rng.uniform(-0.01, 0.45, 300), forwards[::-1],
                            np.repeat(run.reading_times_s[::37], 2), run.image_arrival_times_s])
    shown = set()
    for t in times:
        context.SetTime(t)
        k = np.flatnonzero(run.reading_times_s <= t)
        arrived = np.flatnonzero(run.image_arrival_times_s <= t)
        position = source.GetOutputPort("measured_position").Eval(context)
        stamp = source.GetOutputPort("measurement_time").Eval(context)[0]
        frame = source.GetOutputPort("depth_frame").Eval(context)
        if len(k):
            assert stamp == run.reading_times_s[k[-1]]
            np.testing.assert_array_equal(position, run.readings_rad[k[-1]])
        else:
            assert stamp == -1.0
            np.testing.assert_array_equal(position, run.readings_rad[0])
        if not len(arrived):
            assert frame.is_empty
            continue
        i = arrived[np.argmax(run.image_arrival_times_s[arrived])]
        assert frame.sequence == i
        assert frame.capture_time_s == run.image_capture_times_s[i]
        assert frame.arrival_time_s == run.image_arrival_times_s[i]
        np.testing.assert_array_equal(frame.depth_m, run.depth_images_m[i])
        shown.add(i)
    assert shown == set(range(5))  # every image was shown
    # Shown again and again, an image stays one object while it is the latest.
    context.SetTime(0.3)
    first = source.GetOutputPort("depth_frame").Eval(context)
    for t in (0.31, 0.35, 0.4):
        context.SetTime(t)
        assert source.GetOutputPort("depth_frame").Eval(context) is first


def test_latest_at_or_before_answers_as_numpy_searchsorted():
    """The source's incremental lookup against its plain reference, on sorted times with
    repeats, unsorted times and NaN, asked forwards by small and large steps, backwards
    and at the same time again."""
    from drake_tracker.systems.recorded_run_source import LatestAtOrBefore

    rng = np.random.default_rng(5)
    sorted_times = np.sort(np.round(rng.uniform(0.0, 1.0, 200), 2))  # many repeats
    cases = [sorted_times, rng.uniform(0.0, 1.0, 50), np.array([0.1, np.nan, 0.3]),
             np.array([]), np.array([0.5])]
    for times in cases:
        lookup = LatestAtOrBefore(times)
        queries = np.concatenate([np.arange(-0.05, 1.05, 0.003), [0.5, 0.5, 0.2, 2.0, -1.0],
                                  rng.uniform(-0.1, 1.1, 300), sorted_times])
        for t in queries.tolist():
            assert lookup(t) == int(np.searchsorted(times, t, side="right")) - 1, (times, t)
