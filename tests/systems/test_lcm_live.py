"""The live LCM Diagram (``examples/lcm_live.py``): a recorded run published over
``DrakeLcm("memq://")`` as a robot would (``IIWA_STATUS`` at each reading's stamp, an
``lcmt_image_array`` at each image's arrival: ``io/run_lcm_log.run_messages``, the
bytes an LCM log of the run holds) gives the offline tracker's estimates.

What holds, and why not more: every message is taken in at its publication time (the
``LcmInterfaceSystem`` hands it to its subscriber at the start of the next step), so the
tracker's systems see exactly the readings and images ``RecordedRunSource`` shows
(``tests/offline_vs_diagram.py``). The offline tracker applies an image the moment it
arrives; the Diagram at its first image check after that (``DepthImageToFrame`` at 5h/8
of a period, the CPF system at 3h/4: up to one encoder period h later). So the estimates
are equal (1e-9) at every sample with no image arrival in the 2.5 h before it
(``assert_same_when_settled``, the test the recorded-run Diagram passes), and differ
in between, where the Diagram has not applied the image yet; the same images are applied.
Against the recorded-run Diagram (``RecordedRunSource``, which hands the CPF system a
``DepthFrame`` directly) the estimates are equal at every sample but those within h of
an image that arrived between 5h/8 and 3h/4 of a period: that one the recorded-run
Diagram's CPF system sees at once, while ``DepthImageToFrame`` converts it a period
later. Image arrays the tracker cannot use, published between the good ones, are skipped and
counted and change nothing.
"""

import numpy as np
import pytest
from drake import lcmt_image, lcmt_viewer_draw
from example_modules import load_example
from fast_params import small_params
from offline_vs_diagram import H, assert_same_when_settled, feed, simulate
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from drake_tracker.io.lcm_messages import depth_image_message, image_array_message
from drake_tracker.io.run_lcm_log import run_messages
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.tracker import Tracker

pytest.importorskip("pydrake.manipulation")


def _bad_arrays(run):
    """(log µs, channel, bytes): a colour-only array and a depth image of the wrong size,
    each half-way between two image arrivals."""
    colour = depth_image_message(0, np.ones((6, 8), np.float32))
    colour.pixel_format = lcmt_image.PIXEL_FORMAT_RGB
    small = depth_image_message(0, np.ones((6, 8), np.float32))
    bad = []
    for k, image in ((3, colour), (9, small)):
        t_us = int(round((run.image_arrival_times_s[k] + 1 / 60) * 1e6))
        image.header.utime = t_us
        bad.append((t_us, "DRAKE_RGBD_CAMERA_IMAGES", image_array_message(t_us, [image])))
    return bad


def _publish(simulator, bus, messages, times, sample):
    """Publishes ``messages`` (log µs, channel, bytes) on ``bus`` at their log times while
    the Simulator advances, and returns ``sample()`` at each of ``times``."""
    samples, i = [], 0
    for t in times:
        while i < len(messages) and messages[i][0] / 1e6 <= t:
            log_us, channel, data = messages[i]
            simulator.AdvanceTo(log_us / 1e6)
            bus.Publish(channel, data)
            i += 1
        simulator.AdvanceTo(t)
        samples.append(sample())
    assert i == len(messages)
    return samples


def test_the_lcm_diagram_gives_the_offline_estimates(apollo):
    run = synthetic_run(apollo, duration_s=0.6, encoder_rate_hz=1.0 / H,
                        seed=4).stamped_in_microseconds()
    p = small_params()
    p.image.num_particles, p.image.seed = 40, 4
    offline, applied = feed(Tracker(apollo, run.camera_intrinsics, p), run)

    bus = DrakeLcm("memq://")
    # The hand pose on a bus of its own, handled here, between the Simulator's steps: a
    # Python handler on the bus of the Diagram's LcmInterfaceSystem runs inside
    # Simulator.AdvanceTo, which newer pydrake calls without the GIL (drake 1.58 on
    # Python 3.12: a segmentation fault in pydrake's lcm module, building the message's
    # bytes).
    pose_bus = DrakeLcm("memq://")
    live = load_example("lcm_live.py").build(bus, apollo, run.camera_intrinsics, H, p,
                                             pose_lcm=pose_bus)
    published = []
    pose_bus.Subscribe("TRACKER_HAND_POSE", published.append)
    simulator = Simulator(live.diagram)
    context = simulator.get_mutable_context()
    bank_context = live.tracker.kalman_bank.GetMyContextFromRoot(context)
    messages = sorted([*run_messages(run, base_us=0), *_bad_arrays(run)],
                      key=lambda m: m[0])
    diagram = _publish(simulator, bus, messages, run.reading_times_s + 0.6 * H,
                       lambda: live.tracker.estimated_position.Eval(bank_context).copy())

    status_context = live.status.GetMyContextFromRoot(context)
    assert live.status.get_time_measured_output_port().Eval(status_context)[0] == \
        run.reading_times_s[-1]
    cpf = live.tracker.image_update
    state = cpf.state(cpf.GetMyContextFromRoot(context))
    assert state.in_flight is None
    assert sum(applied.values()) > 5
    assert state.images_applied == sum(applied.values())
    assert live.images.skipped == {"depth images not usable": 2}
    assert_same_when_settled(run, diagram, offline)
    recorded, _ = simulate(apollo, run, p)
    samples = run.reading_times_s + 0.6 * H
    arrivals = run.image_arrival_times_s
    late = arrivals[(arrivals % H > 0.625 * H) & (arrivals % H <= 0.75 * H)]
    assert len(late) > 0
    converted_later = np.array([np.any((late < t) & (t - late < H)) for t in samples])
    difference = np.max(np.abs(np.array(diagram) - np.array(recorded)), axis=1)
    assert np.max(difference[~converted_later]) <= 1e-9

    # The hand pose went out once per period, as the estimate's X_CE in float32.
    simulator.AdvanceTo(run.reading_times_s[-1] + 0.8 * H)
    while pose_bus.HandleSubscriptions(0):
        pass
    assert len(published) >= len(run.reading_times_s) - 1
    message = lcmt_viewer_draw.decode(published[-1])
    X_CE = live.tracker.X_CE.Eval(bank_context)
    assert message.link_name == ["end_effector"]
    assert message.timestamp == round(1000 * (run.reading_times_s[-1] + 0.75 * H))
    np.testing.assert_array_equal(message.position[0],
                                  np.float32(X_CE.translation()).astype(float))
    q = X_CE.rotation().ToQuaternion()
    np.testing.assert_array_equal(message.quaternion[0],
                                  np.float32([q.w(), q.x(), q.y(), q.z()]).astype(float))


def test_two_cameras_on_their_own_channels_give_the_offline_estimates():
    """A two-camera run published as Drake publishes named cameras (each on
    ``DRAKE_RGBD_CAMERA_IMAGES_<name>``) into the example's Diagram of several cameras
    (``AddTracker(cameras=...)``): the offline tracker's estimates wherever no image is
    in flight (a frame that comes at the check of the other camera's is taken one check
    later, as in ``test_offline_equals_diagram``), and every image applied."""
    from offline_vs_diagram import feed_cameras

    from drake_tracker.io.replay import model_for_run
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario

    run = simulate_and_record(load_scenario("occlusion-lasting-2cam/constant"),
                              duration_s=1.0).stamped_in_microseconds()
    model = model_for_run(run)
    h = float(np.median(np.diff(run.reading_times_s)))
    times = run.reading_times_s + 0.6 * h
    p = small_params()
    p.image.seed = 5
    offline, applied = feed_cameras(Tracker(model, params=p, cameras=run.intrinsics_by_camera),
                                    run, times)
    assert min(applied.values()) > 5

    bus, pose_bus = DrakeLcm("memq://"), DrakeLcm("memq://")
    live = load_example("lcm_live.py").build(bus, model, run.intrinsics_by_camera, h, p,
                                             pose_lcm=pose_bus)
    assert list(live.images_by_camera) == run.camera_names
    simulator = Simulator(live.diagram)
    context = simulator.get_mutable_context()
    bank_context = live.tracker.kalman_bank.GetMyContextFromRoot(context)
    messages = list(run_messages(run, base_us=0))
    assert {m[1] for m in messages} == {"IIWA_STATUS", "DRAKE_RGBD_CAMERA_IMAGES_camera",
                                        "DRAKE_RGBD_CAMERA_IMAGES_post_camera"}
    diagram = _publish(simulator, bus, messages, times,
                       lambda: live.tracker.estimated_position.Eval(bank_context).copy())
    cpf = live.tracker.image_update
    state = cpf.state(cpf.GetMyContextFromRoot(context))
    assert state.images_applied + (state.in_flight is not None) == sum(applied.values())
    assert all(a.skipped == {} for a in live.images_by_camera.values())
    first = next(k for k, e in enumerate(offline) if e is not None)
    arrivals = np.concatenate([run.image_arrival_times_s] + [
        c.arrival_times_s for c in run.other_cameras])
    assert_same_when_settled(run, diagram, [None if e is None else e.positions
                                            for e in offline], first, 2 * h, h, arrivals)
