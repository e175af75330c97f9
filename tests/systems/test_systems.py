"""The tracker's Drake systems: each through its ports, Contexts copied and simulated
again, the image update on the worker thread (the whole Diagram against the offline
tracker: ``tests/systems/test_offline_equals_diagram.py``)."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import VectorLogSink

from drake_tracker.core.filter.start import new_bank_and_belief
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.systems.add_tracker import AddTracker
from drake_tracker.systems.delay_buffer_system import DelayBufferSystem
from drake_tracker.systems.messages import ImageObservationMessage
from drake_tracker.systems.recorded_run_source import RecordedRunSource

CAMERA = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))


def params(seed: int = 0) -> TrackerParams:
    p = TrackerParams()
    p.image.num_particles = 40
    p.image.seed = seed
    return p


def test_delay_buffer_system_reports_why_an_image_has_no_prior(apollo):
    system = DelayBufferSystem(model=apollo, params=params(), period_s=0.01)
    context = system.CreateDefaultContext()
    system.GetInputPort("image_observation").FixValue(context, ImageObservationMessage())
    frame = DepthFrame(0.0, 0.05, np.ones((60, 80), np.float32), 0)
    system.GetInputPort("depth_frame").FixValue(context, frame)
    prior = system.GetOutputPort("image_prior").Eval(context)
    assert prior.anchor is None and "no joint reading" in prior.problem
    system.GetInputPort("measured_position").FixValue(
        context, np.zeros(len(apollo.robot_joint_names)))
    system.GetInputPort("measurement_time").FixValue(context, [0.0])
    Simulator(system, context).AdvanceTo(0.005)
    prior = system.GetOutputPort("image_prior").Eval(context)
    assert prior.anchor is not None and prior.anchor.prior.shape == (5, apollo.num_joints)
    system.GetInputPort("depth_frame").FixValue(
        context, DepthFrame(1.0, 1.0, np.ones((60, 80), np.float32), 1))
    assert "future" in system.GetOutputPort("image_prior").Eval(context).problem


def test_the_buffer_takes_an_observation_once_and_again_after_a_rewound_context(apollo):
    """The buffer reads ``image_observation`` only when its value changed (a cache entry
    on the port): a message is taken once; a context set back to before it (its fixed
    port unchanged) takes it again, as a fresh run would."""
    from drake_tracker.core.filter.angle_observation import AngleObservation
    from drake_tracker.core.filter.kalman import MEAN_A, VAR_A

    system = DelayBufferSystem(model=apollo, params=params(), period_s=0.01)
    context = system.CreateDefaultContext()
    port = system.GetInputPort("image_observation")
    port.FixValue(context, ImageObservationMessage())
    system.GetInputPort("depth_frame").FixValue(context, DepthFrame.empty())
    system.GetInputPort("measured_position").FixValue(
        context, np.zeros(len(apollo.robot_joint_names)))
    simulator = Simulator(system, context)
    for k in range(5):  # five readings
        system.GetInputPort("measurement_time").FixValue(context, [0.01 * k])
        simulator.AdvanceTo(0.01 * k + 0.005)
    saved = context.Clone()
    anchor = system.state(context).buffer.image_anchor(0.02)
    observation = AngleObservation.from_posterior(
        anchor.prior, anchor.prior[MEAN_A] + 0.01, 0.5 * anchor.prior[VAR_A])
    port.FixValue(context, ImageObservationMessage(1, 0, 0.02, observation, anchor))
    taken = []
    for _ in range(2):
        simulator.AdvanceTo(context.get_time() + 0.01)
        state = system.state(context)
        taken.append((state.last_observation_id, state.correction.id))
        context.SetTimeStateAndParametersFrom(saved)
        simulator.Initialize()
        assert system.state(context).last_observation_id == 0
    assert taken == [(1, 1), (1, 1)]


def _simulate(apollo, run, p, h):
    builder = DiagramBuilder()
    source = builder.AddSystem(RecordedRunSource(run))
    tracker = AddTracker(builder, model=apollo, camera=run.camera_intrinsics, params=p,
                         measured_position=source.GetOutputPort("measured_position"),
                         measurement_time=source.GetOutputPort("measurement_time"),
                         depth=source.GetOutputPort("depth_frame"), encoder_period_s=h)
    logger = builder.AddSystem(VectorLogSink(apollo.num_joints))
    builder.Connect(tracker.port("estimated_position"), logger.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    return diagram, simulator, tracker, logger


def test_diagram_context_can_be_copied_and_resimulated(apollo):
    h = 1.0 / 200.0
    run = synthetic_run(apollo, duration_s=0.3, encoder_rate_hz=200.0, seed=5)
    diagram, simulator, tracker, _ = _simulate(apollo, run, params(seed=5), h)
    simulator.AdvanceTo(0.12)
    saved = simulator.get_context().Clone()
    simulator.AdvanceTo(0.25)
    port = tracker.port("estimated_position")
    first = port.Eval(tracker.kalman_bank.GetMyContextFromRoot(simulator.get_context())).copy()
    simulator.get_mutable_context().SetTimeStateAndParametersFrom(saved)
    simulator.Initialize()
    simulator.AdvanceTo(0.25)
    second = port.Eval(tracker.kalman_bank.GetMyContextFromRoot(simulator.get_context()))
    np.testing.assert_array_equal(first, second)


def test_a_copied_context_shares_the_stored_states_and_neither_sees_the_other(apollo):
    """The systems' abstract states are never modified once stored (Drake copies them at
    every update, so the copies share them): a Context copied mid-run keeps its own
    buffer, gates and counts while the original goes on. The bank's state is numbers
    (a discrete update), read back through ``bookkeeping``."""
    h = 1.0 / 200.0
    run = synthetic_run(apollo, duration_s=0.3, encoder_rate_hz=200.0, seed=5)
    diagram, simulator, tracker, _ = _simulate(apollo, run, params(seed=5), h)
    simulator.AdvanceTo(0.12)
    systems = (tracker.delay_buffer, tracker.image_update)
    bank_system = tracker.kalman_bank

    def snapshot(context):
        buffer, cpf = (s.GetMyContextFromRoot(context).get_abstract_state(0).get_value()
                       for s in systems)
        bank = bank_system.bookkeeping(bank_system.GetMyContextFromRoot(context))
        return (len(buffer.buffer), buffer.buffer.now_s, buffer.readings.last_raw_s,
                buffer.readings.clock.latest_s, buffer.image_clock.latest_s,
                buffer.correction.id, bank.reading_id,
                bank.time_s, cpf.last_sequence, cpf.images_applied, cpf.message.id)

    saved = simulator.get_context().Clone()
    before = snapshot(saved)
    assert before == snapshot(simulator.get_context())
    for system in systems:  # shared, not copied
        assert (system.GetMyContextFromRoot(saved).get_abstract_state(0).get_value() is
                system.GetMyContextFromRoot(simulator.get_context()).get_abstract_state(0)
                .get_value())
    simulator.AdvanceTo(0.25)
    after = snapshot(simulator.get_context())
    assert snapshot(saved) == before
    assert after[1] > before[1] and after[6] > before[6] and after[10] > before[10]
    # A check that finds no new frame does nothing (Drake applies no update): per tick
    # the buffer, plus one per frame the image update saw; the bank's are discrete.
    ticks = int(round(0.25 / h)) + 1
    frames = int(np.sum(run.image_arrival_times_s <= 0.25))
    assert simulator.get_num_unrestricted_updates() <= ticks + frames
    assert 0 < simulator.get_num_discrete_updates() <= ticks


def _cpf_system_with_a_frame(apollo, p):
    from drake_tracker.core.filter.belief_buffer import ImageAnchor
    from drake_tracker.core.render.configurations import default_view_configuration
    from drake_tracker.systems.cpf_system import CpfImageUpdateSystem
    from drake_tracker.systems.messages import ImagePrior

    system = CpfImageUpdateSystem(model=apollo, camera=CAMERA, params=p, period_s=0.01)
    context = system.CreateDefaultContext()
    run = synthetic_run(apollo, duration_s=0.2, seed=2)
    frame = DepthFrame(0.0, 0.05, run.depth_images_m[0], 0)
    _, belief = new_bank_and_belief(resolve_tracker_params(p, apollo),
    default_view_configuration(apollo)[
        [apollo.joint_names.index(n) for n in apollo.robot_joint_names]])
    system.GetInputPort("depth_frame").FixValue(context, frame)
    anchor = ImageAnchor(0.0, 0.0, belief, np.zeros(apollo.num_joints))
    system.GetInputPort("image_prior").FixValue(context, ImagePrior(0, 0.0, anchor, ""))
    return system, context, frame, anchor


def test_cpf_system_processes_each_new_frame_once_through_its_ports(apollo, caplog):
    import logging

    from drake_tracker.systems.messages import ImagePrior

    p = params()
    p.image.min_image_interval_s = 0.0
    p.image.update_latency_s = 0.0  # at once (the worker thread: the test below)
    system, context, frame, anchor = _cpf_system_with_a_frame(apollo, p)
    simulator = Simulator(system, context)
    simulator.AdvanceTo(0.015)
    message = system.GetOutputPort("image_observation").Eval(context)
    assert message.id == 1 and message.sequence == 0 and message.image_time_s == 0.0
    assert np.all(np.isfinite(message.observation.precision))
    simulator.AdvanceTo(0.035)  # the same frame again: nothing new
    assert system.GetOutputPort("image_observation").Eval(context).id == 1
    # A malformed image is skipped with a warning, not raised inside the simulation.
    bad = DepthFrame(0.03, 0.06, np.ones((10, 10), np.float32), 1)
    system.GetInputPort("depth_frame").FixValue(context, bad)
    system.GetInputPort("image_prior").FixValue(context, ImagePrior(1, 0.03, anchor, "", 1))
    with caplog.at_level(logging.WARNING):
        simulator.AdvanceTo(0.055)
    assert "image 1 skipped" in caplog.text
    assert system.GetOutputPort("image_observation").Eval(context).id == 1


def test_cpf_system_applies_a_worker_update_after_its_latency_with_the_same_result(apollo):
    """With ``update_latency_s`` > 0 the update runs on the worker thread and its message
    appears that much later, equal to the one computed at once; a frame that is due
    while an update is in flight applies that update first."""
    from drake_tracker.systems.messages import ImagePrior

    messages = {}
    for latency in (0.0, 0.03):
        p = params()
        p.image.min_image_interval_s = 0.0
        p.image.update_latency_s = latency
        system, context, frame, anchor = _cpf_system_with_a_frame(apollo, p)
        simulator = Simulator(system, context)
        simulator.AdvanceTo(0.025)  # ticks at 0, 0.01, 0.02
        port = system.GetOutputPort("image_observation")
        in_flight = context.get_abstract_state(0).get_value().in_flight
        if latency:
            assert port.Eval(context).id == 0 and in_flight.due_s == pytest.approx(0.03)
            simulator.AdvanceTo(0.035)
            assert context.get_abstract_state(0).get_value().in_flight is None
        messages[latency] = port.Eval(context)
        assert messages[latency].id == 1 and messages[latency].sequence == 0
    for name in ("precision", "information"):
        np.testing.assert_array_equal(getattr(messages[0.0].observation, name),
                                      getattr(messages[0.03].observation, name))
    # A due frame at 0.01 s, while image 0 is in flight until 0.05 s: image 0 first.
    p.image.update_latency_s = 0.05
    system, context, frame, anchor = _cpf_system_with_a_frame(apollo, p)
    simulator = Simulator(system, context)
    simulator.AdvanceTo(0.005)
    system.GetInputPort("depth_frame").FixValue(context, DepthFrame(0.01, 0.01, frame.depth_m, 1))
    system.GetInputPort("image_prior").FixValue(context, ImagePrior(1, 0.01, anchor, ""))
    simulator.AdvanceTo(0.015)
    s = context.get_abstract_state(0).get_value()
    assert s.message.id == 1 and s.message.sequence == 0 and s.in_flight is None
    # Image 1 is put off until the buffer has taken image 0's update into its prior.
    system.GetInputPort("image_prior").FixValue(context, ImagePrior(1, 0.01, anchor, "", 1))
    simulator.AdvanceTo(0.025)
    s = context.get_abstract_state(0).get_value()
    assert s.in_flight.frame.sequence == 1 and s.in_flight.due_s == pytest.approx(0.07)


def test_deadline_waits_count_done_and_late_updates_and_what_they_raise():
    import threading
    import time
    from concurrent.futures import Future

    from drake_tracker.systems.image_update_worker import DeadlineWaits

    waits = DeadlineWaits()
    done = Future()
    done.set_result(7)
    assert waits.join(done) == 7 and (waits.on_time, waits.late, waits.waited_s) == (1, 0, 0.0)
    for value in (8, ValueError("update failed")):
        slow = Future()

        def finish(future=slow, value=value):
            time.sleep(0.05)
            if isinstance(value, Exception):
                future.set_exception(value)
            else:
                future.set_result(value)

        threading.Thread(target=finish).start()
        if isinstance(value, Exception):
            with pytest.raises(ValueError, match="update failed"):
                waits.join(slow)
        else:
            assert waits.join(slow) == 8
    assert waits.on_time == 1 and waits.late == 2 and waits.waited_s >= 0.09
    assert waits.late_searches == 0  # neither was started as a search
    slow = Future()
    threading.Thread(target=lambda: (time.sleep(0.05), slow.set_result(9))).start()
    assert waits.join(slow, search=True) == 9
    assert (waits.late, waits.late_searches) == (3, 1)
    searched = Future()
    searched.set_result(10)  # a search done in time is on time, whatever it was
    assert waits.join(searched, search=True) == 10
    assert (waits.on_time, waits.late_searches) == (2, 1)


@pytest.mark.parametrize("latency_s", [0.0, 0.01])
def test_cpf_system_counts_the_updates_its_deadline_waited_for(apollo, latency_s):
    """An update slower than the simulated latency (0.2 s of wall time here, while the
    Simulator reaches its deadline at once) is counted late, with the wait; at
    ``update_latency_s`` 0 nothing runs on the worker and nothing is counted."""
    import time

    p = params()
    p.image.update_latency_s = latency_s
    system, context, frame, anchor = _cpf_system_with_a_frame(apollo, p)
    observe = system.processor.observe

    def slow_observe(*args):
        time.sleep(0.2)
        return observe(*args)

    system.processor.observe = slow_observe
    Simulator(system, context).AdvanceTo(0.025)
    s = context.get_abstract_state(0).get_value()
    assert s.message.id == 1 and s.in_flight is None
    waits = system.deadline_waits
    if latency_s == 0:
        assert (waits.on_time, waits.late, waits.waited_s) == (0, 0, 0.0)
    else:
        assert waits.on_time == 0 and waits.late == 1 and waits.waited_s >= 0.15
        # The system's first image finds no arm acquired: its update was a search.
        assert waits.late_searches == 1


def test_cpf_system_warns_when_the_prior_never_takes_in_its_updates(apollo, caplog):
    """A prior port that is not the buffer fed by image_observation: the frame is put
    off for one check, then used with a warning (never stalled in silence)."""
    import logging

    from drake_tracker.systems.messages import ImagePrior

    p = params()
    p.image.min_image_interval_s = 0.0
    system, context, frame, anchor = _cpf_system_with_a_frame(apollo, p)
    simulator = Simulator(system, context)
    simulator.AdvanceTo(0.1)  # image 0's update is applied at 0.08 s
    assert context.get_abstract_state(0).get_value().message.id == 1
    system.GetInputPort("depth_frame").FixValue(context, DepthFrame(0.1, 0.1, frame.depth_m, 1))
    system.GetInputPort("image_prior").FixValue(context, ImagePrior(1, 0.1, anchor, ""))
    with caplog.at_level(logging.WARNING):
        simulator.AdvanceTo(0.125)
    assert "holds image updates up to 0, not 1" in caplog.text
    assert context.get_abstract_state(0).get_value().in_flight.frame.sequence == 1


def test_the_image_update_worker_runs_in_a_forked_child():
    """A child forked after the worker started gets a worker of its own (the parent's
    thread does not exist in it: without one, its updates would wait forever)."""
    import multiprocessing

    from drake_tracker.systems.image_update_worker import submit_image_update

    assert submit_image_update(pow, 2, 10).result(timeout=10) == 1024
    context = multiprocessing.get_context("fork")
    with context.Pool(1) as pool:
        assert pool.apply_async(_in_child).get(timeout=60) == 1024


def _in_child() -> int:
    from drake_tracker.systems.image_update_worker import submit_image_update

    return submit_image_update(pow, 2, 10).result(timeout=10)
