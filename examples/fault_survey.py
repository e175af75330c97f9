"""Bad-input survey (issue 14): tries a catalogue of bad inputs against the offline
``Tracker``, the parameter and scenario loaders, recordings and the Diagram, and sorts
each outcome into one class:

* ``clear error``: a documented exception (ValueError, FileNotFoundError) naming the problem;
* ``unclear error``: such an exception whose message does not name it;
* ``warned skip``: the sample is not used, and a warning was logged;
* ``handled``: the input is valid or made valid (e.g. a uint16 image, an out-of-order
  image applied at its time, a clock re-anchored), the tracker goes on;
* ``silent skip``: the sample is not used and nothing was logged;
* ``accepted``: a bad parameter or scenario value loaded without complaint;
* ``crash``: any other exception (a raw Python error);
* ``NaN estimate``: the estimate is not finite afterwards;
* ``lost data``: good readings or a good image after the fault were not used.

    python examples/fault_survey.py          # prints the table and the counts (~1-2 min)

Every tracker case starts from a copy of one tracker that has tracked 0.3 s of a
synthetic run (``drake_tracker.io.synthetic``), applies its fault, then feeds the run's next
good readings and image: they must be used, and the estimate must be finite.
"""

from __future__ import annotations

import copy
import logging
import sys
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.io.replay import replay_run
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.metrics import pose_errors
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model, robot_preset
from drake_tracker.tracker import Tracker

CLEAR_ERRORS = (ValueError, FileNotFoundError)
FAULT_S = 0.3  # the tracker has tracked up to here when a fault is applied
#: Good readings fed after a fault (0.3 s at 200 Hz), with the images that arrive then.
POST_READINGS = 60


class Captured(logging.Handler):
    """Collects the WARNING records of drake_tracker's loggers."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def small_params() -> TrackerParams:
    p = TrackerParams()
    p.image.num_particles = 20
    p.image.annealing_betas = [0.1, 1.0]
    p.image.min_image_interval_s = 0.0
    return p


class Bench:
    """The model, the synthetic run and a tracker that has tracked it up to FAULT_S."""

    def __init__(self):
        self.model = build_tracker_model(robot_preset("apollo"))
        self.run = synthetic_run(self.model, duration_s=1.2, encoder_rate_hz=200.0, seed=1)
        self.tracker = Tracker(self.model, self.run.camera_intrinsics, small_params())
        self.k0 = int(np.searchsorted(self.run.reading_times_s, FAULT_S))
        self.feed(self.tracker, 0, self.k0)
        self.image = self.run.depth_images_m[5]

    def feed(self, tracker, k_from, k_to, shift_s=0.0, every_image=True) -> list[bool]:
        run, applied = self.run, []
        for k in range(k_from, k_to):
            t = run.reading_times_s[k]
            for j in np.flatnonzero((run.image_arrival_times_s <= t) & (
                    run.image_arrival_times_s > (run.reading_times_s[k - 1] if k else -1))):
                if every_image:
                    applied.append(tracker.add_image(DepthFrame(
                        run.image_capture_times_s[j], run.image_arrival_times_s[j],
                        run.depth_images_m[j], int(j))))
            tracker.add_reading(t + shift_s, run.readings_rad[k])
        return applied

    def fresh(self) -> Tracker:
        shared = (self.model, self.tracker.readout, self.tracker.images)
        return copy.deepcopy(self.tracker, memo={id(x): x for x in shared})

    def frame(self, depth="good", capture=None, arrival=None, sequence=9) -> DepthFrame:
        t = self.run.reading_times_s[self.k0 - 1] - 0.02 if capture is None else capture
        return DepthFrame(t, t + 0.05 if arrival is None else arrival,
                          self.image if isinstance(depth, str) else depth, sequence)


# ----------------------------------------------------------------- tracker cases
GOOD = object()  # the run's own stamp or value


def reading_case(bench, tracker, stamp=GOOD, value=GOOD, repeat=1, shift_after=0.0):
    """A reading with a bad stamp or value (``repeat`` times, 5 ms apart); then the
    run's next readings (stamps shifted by ``shift_after``, a clock that stayed
    stepped). Returns whether the first bad reading was used, and the post shift."""
    k = bench.k0
    before = tracker.estimate().time_s
    for r in range(repeat):
        t = (bench.run.reading_times_s[k + r] if stamp is GOOD else
             stamp if r == 0 else stamp + 0.005 * r)
        tracker.add_reading(t, bench.run.readings_rad[k + r] if value is GOOD else value)
        if r == 0:
            used = tracker.estimate().time_s != before
    return used, k + repeat, shift_after


def image_case(bench, tracker, **frame_args):
    return tracker.add_image(bench.frame(**frame_args)), bench.k0, 0.0


def tracker_cases(bench) -> list:
    r, model = bench.run, bench.model
    n, t_last = len(model.robot_joint_names), r.reading_times_s[bench.k0 - 1]
    good = r.readings_rad[bench.k0]
    h, w = bench.image.shape
    img, cases = bench.image, []

    def add(name, fn, keyword="", **kw):
        cases.append((name, lambda tr: fn(bench, tr, **kw), keyword))

    stamps = {"NaN": np.nan, "+inf": np.inf, "-inf": -np.inf, "+1000 s glitch":
              t_last + 1000, "1e6 s glitch": 1e6, "1e300 s": 1e300, "+31 s glitch":
              t_last + 31, "equal to the previous": t_last, "1 ms before the previous":
              t_last - 0.001, "-5 s": -5.0, "0": 0.0}
    for label, s in stamps.items():
        add(f"reading stamp {label}", reading_case, "stamp", stamp=s)
    add("reading stamp as a string 'x'", reading_case, "stamp", stamp="x")
    add("reading stamp None", reading_case, "stamp", stamp=None)
    add("reading values [None, ...]", reading_case, "not finite", value=[None] * n)
    add("reading clock steps back 1 s and stays", reading_case, "", stamp=t_last - 0.995,
        repeat=8, shift_after=-1.0)
    add("reading clock steps forward 200 s and stays", reading_case, "", stamp=t_last + 200,
        repeat=8, shift_after=200.0)
    add("reading clock steps forward 1 s and stays", reading_case, "",
        stamp=t_last + 1.005, repeat=8, shift_after=1.0)
    values = {"NaN in one joint": np.where(np.arange(n) == 2, np.nan, good),
              "all NaN": np.full(n, np.nan), "+inf": np.full(n, np.inf),
              "-inf in one joint": np.where(np.arange(n) == 0, -np.inf, good),
              "1e300": np.full(n, 1e300), "too short": good[:-1], "too long":
              np.append(good, 0.0), "2-D": good[None], "empty": np.zeros(0),
              "strings": np.array(["a"] * n), "None": None, "a list": list(good),
              "integers": np.round(good).astype(int), "1e6 rad (finite)": good + 1e6}
    for label, v in values.items():
        add(f"reading values {label}", reading_case, "joint", value=v)
    add("reading values NaN for 0.5 s", reading_case, "not finite",
        value=np.full(n, np.nan), repeat=100)
    depths = {"float64 metres": img.astype(np.float64), "float16 metres":
              img.astype(np.float16), "uint16 millimetres": np.round(img * 1e3).astype(
                  np.uint16), "uint16 with zeros": np.where(np.arange(w) < 10, 0, np.round(
                      img * 1e3)).astype(np.uint16), "int32 millimetres": np.round(
                  img * 1e3).astype(np.int32), "uint8": np.clip(img * 50, 0, 255).astype(
                  np.uint8), "bool": img > 1, "complex": img.astype(np.complex64),
              "object": img.astype(object), "float millimetres": img * 1000.0,
              "float centimetres": img * 100.0, "negative pixels": np.where(
                  np.arange(w) < 5, -1.0, img).astype(np.float32), "all zero":
              np.zeros_like(img), "all NaN": np.full_like(img, np.nan), "all +inf":
              np.full_like(img, np.inf), "all beyond range (7 m)": np.full_like(img, 7.0),
              "all at 1 cm": np.full_like(img, 0.01), "transposed": img.T, "half size":
              img[::2, ::2], "double size": np.kron(img, np.ones((2, 2), np.float32)),
              "(H, W, 1)": img[:, :, None], "(H, W, 3)": np.repeat(img[:, :, None], 3, 2),
              "1-D": img.ravel(), "empty (0, 0)": np.zeros((0, 0), np.float32),
              "a list of lists": img.tolist(), "None": None}
    keywords = {"float millimetres": "millimetres", "float centimetres": "", "negative "
                "pixels": "negative", "transposed": "shape", "half size": "shape",
                "double size": "shape", "(H, W, 3)": "shape", "1-D": "shape",
                "empty (0, 0)": "empty", "int32 millimetres": "dtype", "uint8": "dtype",
                "bool": "dtype", "complex": "dtype", "object": "dtype"}
    for label, d in depths.items():
        add(f"image {label}", image_case, keywords.get(label, "depth"), depth=d)
    frames = {"capture stamp NaN": dict(capture=np.nan), "capture stamp +inf":
              dict(capture=np.inf), "capture stamp -inf": dict(capture=-np.inf),
              "from the future": dict(capture=t_last + 0.2), "far future (1e6 s)":
              dict(capture=1e6), "older than the horizon": dict(capture=t_last - 2.0),
              "before the first reading": dict(capture=-1.0), "out of order (50 ms late)":
              dict(capture=t_last - 0.15), "arrival before capture":
              dict(arrival=t_last - 0.1), "arrival NaN": dict(arrival=np.nan),
              "sequence -1 (the empty placeholder)": dict(sequence=-1),
              "sequence restarts at 0": dict(sequence=0)}
    for label, f in frames.items():
        add(f"image {label}", image_case, "sequence" if "-1" in label else "stamp", **f)
    add("image the empty placeholder (DepthFrame.empty())", lambda b, tr: (
        tr.add_image(DepthFrame.empty()), b.k0, 0.0))
    add("image twice (same stamp)", lambda b, tr: (image_case(b, tr)[0] and
                                                    image_case(b, tr)[0], b.k0, 0.0))
    cases.append(("image before any reading", lambda tr: (Tracker(
        model, r.camera_intrinsics, small_params()).add_image(bench.frame()), None, 0.0), ""))
    return cases


def run_tracker_case(bench, fn, keyword) -> tuple[str, str]:
    tracker = bench.fresh()
    try:
        used, k_next, shift = fn(tracker)
    except CLEAR_ERRORS as err:
        return ("clear error" if keyword.lower() in str(err).lower() else "unclear error",
                str(err))
    except Exception as err:  # noqa: BLE001 - the survey's point
        return "crash", f"{type(err).__name__}: {err}"
    if k_next is None:  # a case with its own tracker
        return ("handled" if used else "warned skip"), ""
    estimate = tracker.estimate()
    if not np.all(np.isfinite(estimate.positions)):
        return "NaN estimate", ""
    times = bench.run.reading_times_s
    k_end = min(k_next + POST_READINGS, len(times) - 1)
    try:
        applied = bench.feed(tracker, k_next, k_end, shift)
        later = tracker.estimate()
    except Exception as err:  # noqa: BLE001 - the fault broke the tracker for later data
        return "crash", f"later, on good data: {type(err).__name__}: {err}"
    if not np.all(np.isfinite(later.positions)):
        return "NaN estimate", ""
    # The good readings after the fault moved the estimate on by their span (a
    # re-anchored clock shifts the stamps, not the span).
    span, advanced = times[k_end - 1] - times[k_next], later.time_s - estimate.time_s
    if advanced < span - 0.011 or not any(applied):
        return "lost data", (f"the estimate moved on {advanced:.3f} s over {span:.3f} s of "
                             f"good readings; {sum(applied)}/{len(applied)} images applied")
    return ("handled" if used else "skip"), ""


# ----------------------------------------------------------------- Diagram cases
#: The Diagram cases are judged over [DIAGRAM_JUDGED_FROM_S, DIAGRAM_END_S] (s).
DIAGRAM_JUDGED_FROM_S, DIAGRAM_END_S = 0.99, 1.19


def diagram_outcome(bench, stamps=None, sequences=None, arrivals=None, readings=None,
                    images=None) -> tuple[np.ndarray, int]:
    """The Diagram (``AddTracker`` on a recorded-run source with these faults) run to
    the end of the run (1.2 s; the faults are all before 0.6 s): the median hand error
    (mm) over its last 0.2 s, sampled every 10 ms, and the number of images applied.
    (One sample 0.4 s after the fault made a slower convergence look like lost data.)"""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder

    from drake_tracker.systems.add_tracker import AddTracker
    from drake_tracker.systems.recorded_run_source import RecordedRunSource

    run = bench.run
    stamps = run.reading_times_s if stamps is None else stamps
    sequences = np.arange(len(run.image_capture_times_s)) if sequences is None else sequences
    run = replace(run, image_arrival_times_s=run.image_arrival_times_s if arrivals is None
                  else arrivals, readings_rad=run.readings_rad if readings is None
                  else readings, depth_images_m=run.depth_images_m if images is None
                  else images)

    class FaultySource(RecordedRunSource):
        def _calc_time(self, context, output):
            k = self._latest_reading(context.get_time())
            output.SetAtIndex(0, stamps[k] if k >= 0 else -1.0)

        def _calc_frame(self, context, output):
            super()._calc_frame(context, output)
            f = output.get_value()
            if not f.is_empty:
                output.set_value(replace(f, sequence=int(sequences[f.sequence])))

    builder = DiagramBuilder()
    source = builder.AddSystem(FaultySource(run))
    tracker = AddTracker(builder, model=bench.model, camera=run.camera_intrinsics,
                         params=small_params(),
                         measured_position=source.GetOutputPort("measured_position"),
                         measurement_time=source.GetOutputPort("measurement_time"),
                         depth=source.GetOutputPort("depth_frame"), encoder_period_s=0.005)
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    errors = []
    for t in np.arange(DIAGRAM_JUDGED_FROM_S, DIAGRAM_END_S + 1e-9, 0.01):
        simulator.AdvanceTo(t)
        X_CE = tracker.X_CE.Eval(tracker.kalman_bank.GetMyContextFromRoot(context))
        truth = run.truth_X_CE[np.searchsorted(run.truth_times_s, t - 1e-9)]
        errors.append(pose_errors(X_CE.GetAsMatrix4(), truth)[0][0])
    cpf = tracker.image_update.GetMyContextFromRoot(context).get_abstract_state(0)
    return float(np.median(errors)), cpf.get_value().images_applied


def diagram_cases(bench) -> list:
    r = bench.run
    t = r.reading_times_s
    k = bench.k0
    glitch, step = t.copy(), t.copy()
    glitch[k] += 1000.0
    step[k:] -= 1.0
    restart = np.arange(len(r.image_capture_times_s))
    restart[8:] -= 8
    late = r.image_arrival_times_s.copy()
    late[8] = late[9] + 0.012  # two ticks of the tracker's image check after image 9
    together = r.image_arrival_times_s.copy()
    together[8] = together[9] - 0.001  # both arrive within one tick: the port holds one
    burst = r.readings_rad.copy()
    burst[(t >= 0.3) & (t < 0.45)] = np.nan
    millimetres, blank = r.depth_images_m.copy(), r.depth_images_m.copy()
    millimetres[9] *= 1000.0
    blank[9] = np.nan
    return [("Diagram: glitched reading stamp +1000 s", dict(stamps=glitch)),
            ("Diagram: reading clock steps back 1 s and stays", dict(stamps=step)),
            ("Diagram: camera sequence counter restarts", dict(sequences=restart)),
            ("Diagram: an image arrives after the next one", dict(arrivals=late)),
            ("Diagram: two images arrive within one 5 ms tick", dict(arrivals=together)),
            ("Diagram: NaN readings for 0.15 s", dict(readings=burst)),
            ("Diagram: one millimetre image", dict(images=millimetres)),
            ("Diagram: one all-NaN image", dict(images=blank))]


# ----------------------------------------------------------------- the survey
def classify_call(call, keyword) -> tuple[str, str]:
    """A loader case: an error naming ``keyword``, or a load (``keyword`` None: valid)."""
    try:
        call()
    except CLEAR_ERRORS as err:
        if keyword is None:
            return "crash", f"a valid file: {err}"
        return ("clear error" if keyword.lower() in str(err).lower() else "unclear error",
                str(err))
    except Exception as err:  # noqa: BLE001 - the survey's point
        return "crash", f"{type(err).__name__}: {err}"
    return ("handled", "") if keyword is None else ("accepted", "loaded without an error")


def main() -> int:
    from fault_survey_files import file_cases

    handler = Captured()
    logging.getLogger("drake_tracker").addHandler(handler)
    logging.getLogger("drake_tracker").propagate = False
    bench = Bench()
    rows = []

    def record(name, outcome, detail):
        rows.append((name, outcome, detail))
        print(f"{outcome:14s} {name}" + (f"  [{detail[:110]}]" if detail else ""), flush=True)

    for name, fn, keyword in tracker_cases(bench):
        handler.messages.clear()
        outcome, detail = run_tracker_case(bench, fn, keyword)
        if outcome == "skip":
            outcome = "warned skip" if handler.messages else "silent skip"
        if outcome in ("warned skip", "handled") and handler.messages:
            detail = handler.messages[0]
        record(name, outcome, detail)
    with tempfile.TemporaryDirectory() as folder:
        for name, call, keyword in file_cases(Path(folder), bench.run):
            record(name, *classify_call(call, keyword))
    handler.messages.clear()
    nan_run = replace(bench.run, readings_rad=np.where(
        np.arange(len(bench.run.reading_times_s))[:, None] == 50, np.nan,
        bench.run.readings_rad))
    outcome, detail = "handled", ""
    try:
        result = replay_run(nan_run, small_params(), bench.model)
        if not np.all(np.isfinite(result.positions[-5:])):
            outcome = "NaN estimate"
        elif handler.messages:
            outcome, detail = "warned skip", handler.messages[0]
    except Exception as err:  # noqa: BLE001
        outcome, detail = "crash", f"{type(err).__name__}: {err}"
    record("replay: a recording with one NaN reading", outcome, detail)
    clean, clean_applied = diagram_outcome(bench)
    for name, faults in diagram_cases(bench):
        handler.messages.clear()
        try:
            final, applied = diagram_outcome(bench, **faults)
        except Exception as err:  # noqa: BLE001
            record(name, "crash", f"{type(err).__name__}: {err}")
            continue
        warned = handler.messages[0] if handler.messages else ""
        if not np.isfinite(final):
            record(name, "NaN estimate", "")
        elif final > max(2.0 * clean, clean + 5.0):
            record(name, "lost data", f"hand error {final:.1f} mm over the last 0.2 s, clean "
                   f"{clean:.1f} mm; {applied}/{clean_applied} images")
        elif applied < clean_applied:
            record(name, "warned skip" if warned else "silent skip",
                   f"{applied}/{clean_applied} images; {warned}")
        else:
            record(name, "handled", f"hand error {final:.1f} mm (clean {clean:.1f}); {warned}")
    counts = Counter(outcome for _, outcome, _ in rows)
    print(f"\n{len(rows)} bad inputs and faults:")
    for outcome in ("clear error", "warned skip", "handled", "unclear error", "silent skip",
                    "accepted", "crash", "NaN estimate", "lost data"):
        print(f"  {outcome:14s} {counts.get(outcome, 0)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
