"""Simulate a scenario and record it as a :class:`~drake_tracker.io.recording.RecordedRun`.

What is stored (see ``drake_tracker.io.recording`` for the ``.npz`` keys):

* every encoder reading, at the full encoder rate, stamped with its sample time;
* every depth image that arrived during the run, subsampled by ``image_stride``
  (``core.camera.subsample``: pixels (i*stride, j*stride) of the full-resolution
  camera, whatever ``camera.render_stride`` rendered) with the matching intrinsics,
  and its capture and arrival times;
* ground truth (joint angles, bias, camera offset, hand pose in the true camera frame)
  at ``truth_rate_hz`` (default 100 Hz), sampled exactly at ``j / truth_rate_hz``.

The encoder ports are logged inside the Diagram at every simulator step (Drake's
``VectorLogSink``, in C++), and the readings are the logged samples with a new stamp.
The simulator is advanced through the truth times (and, when those are sparser than
the camera's frames, every half frame period); at each stop the truth, the probes and
the depth port are read. (After ``AdvanceTo(t)``, t > 0, the discrete updates at ``t``
are still pending, so the truth at ``t`` is the state at ``t``; the truth at 0 is read
before the first ``AdvanceTo``, which performs the updates at 0.) Stopping at every
1 ms reading instead cost about 0.1 s of wall time per simulated second.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.yaml import yaml_dump, yaml_dump_typed
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, OutputPort
from pydrake.systems.primitives import LogVectorOutput

from drake_tracker.core.sensors.camera import subsample
from drake_tracker.io.recording import CameraImages, RecordedRun
from drake_tracker.progress import SimulatedSecondsBar
from drake_tracker.sim.scenario.load import Scenario, load_scenario, validate_scenario
from drake_tracker.sim.world import AddSimulatedWorld, SimulatedWorld

if TYPE_CHECKING:
    import argparse

#: Signature of the hook that adds systems beside the world; it returns extra output
#: ports to sample at the truth times (stored in ``RecordedRun.extra[name]``).
AddSystems = Callable[[DiagramBuilder, SimulatedWorld], "dict[str, OutputPort] | None"]


def _as_array(value) -> np.ndarray:
    if isinstance(value, RigidTransform):
        return value.GetAsMatrix4()
    return np.array(value, dtype=float, copy=True)


def simulate_and_record(scenario: Scenario, duration_s: float | None = None,
                        image_stride: int = 8, truth_rate_hz: float = 100.0,
                        add_systems: AddSystems | None = None,
                        validate: bool = True, progress: bool = False) -> RecordedRun:
    """Simulates ``scenario`` for ``duration_s`` (default: ``scenario.duration_s``) and
    returns the recorded run. ``add_systems(builder, world)`` may add systems (e.g. a
    tracker, a Meshcat visualizer) and return ports to sample at the truth times into
    ``run.extra`` (RigidTransforms as 4x4). ``run.extra`` also holds
    ``"wall_time_s"`` (simulation wall time, s). ``progress`` shows a bar of simulated
    seconds on stderr."""
    if validate:
        validate_scenario(scenario)
    if image_stride < 1:
        raise ValueError(f"image_stride must be >= 1, got {image_stride}")
    if not truth_rate_hz > 0:
        raise ValueError(f"truth_rate_hz must be > 0, got {truth_rate_hz}")
    duration = float(scenario.duration_s if duration_s is None else duration_s)
    if not duration > 0:
        raise ValueError(f"duration_s must be > 0, got {duration}")

    # Each camera delivers every render_stride-th pixel already: the rest of the stride.
    frame_strides = {}
    for camera in scenario.resolved_cameras():
        if image_stride % camera.render_stride:
            raise ValueError(f"image_stride {image_stride} is not a multiple of camera "
                             f"'{camera.name}''s render_stride {camera.render_stride}")
        frame_strides[camera.name] = image_stride // camera.render_stride
    builder = DiagramBuilder()
    world = AddSimulatedWorld(builder, scenario)
    probes = (add_systems(builder, world) if add_systems else None) or {}
    logs = {name: LogVectorOutput(world.port(name), builder) for name in (
        "measurement_time", "measured_position", "true_bias")}
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    world.set_initial_state(context)

    def reader(port: OutputPort) -> Callable[[], object]:
        """``port``'s value in the simulation's context, as a function (the ports and
        their contexts looked up once, not at each of the 1000 stops a second)."""
        port_context = port.get_system().GetMyContextFromRoot(context)
        return lambda: port.Eval(port_context)

    frame_now = {name: reader(world.depth_port(name)) for name in world.cameras}
    truth_now = {key: reader(world.port(name)) for key, name in (
        ("q", "true_position"), ("offset", "true_camera_offset"), ("X_CE", "true_X_CE"))}
    truth_now["offsets"] = reader(world.truth.GetOutputPort("true_camera_offsets"))
    probe_now = {name: reader(port) for name, port in probes.items()}

    h = world.encoder_period_s
    truth_grid = np.arange(int(np.floor(duration * truth_rate_hz + 1e-9)) + 1) / truth_rate_hz
    stops = truth_grid
    if 1.0 / truth_rate_hz >= 0.5 * world.camera_period_s:  # at most one frame per stop
        half_frame = 0.5 * world.camera_period_s
        stops = np.union1d(stops, np.arange(int(np.floor(duration / half_frame)) + 1)
                           * half_frame)
    stops = np.append(stops, duration + 0.5 * min(h, world.camera_period_s))
    is_truth = np.isin(stops, truth_grid)

    recorded = {name: ([], [], []) for name in world.cameras}  # captures, arrivals, images
    truth = {k: [] for k in ("t", "q", "offset", "X_CE", "offsets")}
    extra = {name: [] for name in probes}
    last_seq = dict.fromkeys(world.cameras, -1)
    start = time.perf_counter()
    def sample_truth_now(t: float) -> None:
        truth["t"].append(t)
        for key, now in truth_now.items():
            truth[key].append(_as_array(now()))
        for name, now in probe_now.items():
            extra[name].append(_as_array(now()))

    bar = SimulatedSecondsBar(duration, enabled=progress)
    for t, sample_truth in zip(stops.tolist(), is_truth.tolist()):
        if progress:
            bar.advance_to(t)
        # The first AdvanceTo(0) also performs the discrete updates at 0 (a dynamic
        # plant steps to time_step_s), so the state at 0 is read before it.
        if sample_truth and t == 0.0:
            sample_truth_now(0.0)
        simulator.AdvanceTo(t)
        for name, now in frame_now.items():
            frame = now()
            if frame.sequence != last_seq[name] and not frame.is_empty:
                if frame.sequence != last_seq[name] + 1:
                    raise RuntimeError(f"camera '{name}' missed depth images "
                                       f"{last_seq[name] + 1}..{frame.sequence - 1}")
                last_seq[name] = frame.sequence
                captures, arrivals, images = recorded[name]
                captures.append(frame.capture_time_s)
                arrivals.append(frame.arrival_time_s)
                images.append(np.array(subsample(frame.depth_m, frame_strides[name]),
                                       np.float32))
        if sample_truth and t > 0.0:
            sample_truth_now(t)
    bar.close()
    wall = time.perf_counter() - start

    # The true bias at a truth time is that of the latest sample at or before it (the
    # encoder port still shows the previous sample while the update at t is pending).
    reading_times, readings, biases = logged_readings(
        {name: log.FindLog(context).data() for name, log in logs.items()}, duration)
    truth_times = np.array(truth["t"], float)
    latest = np.clip(np.searchsorted(reading_times, truth_times + 1e-9, side="right") - 1,
                     0, None)
    truth_bias = np.array(biases, float).reshape(-1, len(world.robot_joint_names))[latest]
    stored = {name: camera.intrinsics.subsampled(frame_strides[name])
              for name, camera in world.cameras.items()}
    names = list(world.cameras)
    offsets = np.array(truth["offsets"], float).reshape(len(truth_times), -1)
    others = [CameraImages(name, stored[name], np.array(recorded[name][0], float),
                           np.array(recorded[name][1], float),
                           np.array(recorded[name][2], np.float32).reshape(
                               -1, stored[name].height, stored[name].width),
                           offsets[:, 6 * j:6 * j + 6]) for j, name in enumerate(names)][1:]
    captures, arrivals, images = recorded[names[0]]
    intrinsics = stored[names[0]]
    n = len(world.robot_joint_names)
    run = RecordedRun(
        robot_config_yaml=yaml_dump(dataclasses.asdict(world.robot_config)),
        joint_names=list(world.robot_joint_names),
        reading_times_s=reading_times,
        readings_rad=np.array(readings, float).reshape(-1, n),
        image_capture_times_s=np.array(captures, float),
        image_arrival_times_s=np.array(arrivals, float),
        depth_images_m=np.array(images, np.float32).reshape(-1, intrinsics.height,
                                                             intrinsics.width),
        camera_intrinsics=intrinsics,
        truth_times_s=truth_times,
        truth_positions_rad=np.array(truth["q"], float).reshape(-1, n),
        truth_bias_rad=truth_bias,
        truth_camera_offset=np.array(truth["offset"], float).reshape(-1, 6),
        truth_X_CE=np.array(truth["X_CE"], float).reshape(-1, 4, 4),
        scenario_yaml=yaml_dump_typed(scenario),
        camera_name=names[0],
        other_cameras=others,
    )
    run.extra.update({name: np.array(v) for name, v in extra.items()})
    run.extra["wall_time_s"] = wall
    run.extra["graphviz"] = diagram.GetGraphvizString(max_depth=1)
    return run


def logged_readings(logged: dict[str, np.ndarray], duration_s: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, readings, biases) of the encoder samples in the per-step logs of
    ``measurement_time``, ``measured_position`` and ``true_bias`` (columns: steps): each
    sample once, at the first step that shows its stamp, within [0, ``duration_s``]."""
    stamps = logged["measurement_time"][0]
    seen = np.maximum.accumulate(np.concatenate([[-np.inf], stamps]))[:-1]
    keep = np.flatnonzero((stamps > seen) & (stamps >= 0) & (stamps <= duration_s + 1e-9))
    return (stamps[keep].astype(float), logged["measured_position"][:, keep].T.copy(),
            logged["true_bias"][:, keep].T.copy())


def run_record(args: argparse.Namespace) -> int:
    """``drake-tracker record --scenario NAME [--out FILE.npz] [--bag FILE.mcap]
    [--lcm-log FILE] [--duration S] [--image-stride N]``: simulates and writes the run as
    ``.npz`` (format in ``drake_tracker.io.recording``), a ROS 2 MCAP bag
    (``io/run_bag.py``) and/or an LCM log (``io/run_lcm_log.py``; then every stamp is in
    whole µs)."""
    scenario = load_scenario(args.scenario)
    lcm_log = getattr(args, "lcm_log", None)
    run = simulate_and_record(scenario, duration_s=args.duration,
                              image_stride=args.image_stride, validate=False, progress=True)
    # An LCM log stamps in µs: then every file gets the µs stamps, so they agree.
    run = run.stamped_in_microseconds() if lcm_log else run.stamped_in_nanoseconds()
    written = []
    if getattr(args, "out", None):
        written.append(str(run.save(args.out)))
    if getattr(args, "bag", None):
        from drake_tracker.io.run_bag import write_run_bag

        count = write_run_bag(run, args.bag)
        written.append(f"{args.bag} ({count} messages)")
    if lcm_log:
        from drake_tracker.io.lcm_messages import camera_text
        from drake_tracker.io.run_lcm_log import write_run_lcm_log

        count = write_run_lcm_log(run, lcm_log)
        flags = (f"--camera {camera_text(run.camera_intrinsics)}" if not run.other_cameras
                 else " ".join(f"--camera {name}={camera_text(camera)}"
                               for name, camera in run.intrinsics_by_camera.items()))
        written.append(f"{lcm_log} ({count} messages; track it with {flags})")
    counts = [(len(c.capture_times_s), c.name, f"{c.intrinsics.width}x{c.intrinsics.height}")
              for c in run.cameras]
    if not run.other_cameras:
        images = f"{counts[0][0]} images ({counts[0][2]})"
    else:
        each = ", ".join(f"{k} from {name} ({size})" for k, name, size in counts)
        images = f"{sum(k for k, _, _ in counts)} images: {each}"
    print(f"recorded '{scenario.name}': {len(run.reading_times_s)} readings, {images}, "
          f"{len(run.truth_times_s)} truth samples, {run.extra['wall_time_s']:.1f} s -> "
          f"{', '.join(written)}")
    return 0
