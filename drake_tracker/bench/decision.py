"""The per-image decision's part of ``drake-tracker bench``: what the recovery costs
beside the image update it guards.

Each image runs the paper's update (the frame's preparation and the CPF search of the
tracked belief) and, around it, the decision of ``docs/method.md`` §7: the estimate's
and the encoders' arms rendered and compared with the image, the restart, the occlusion
estimate, the jump gate, and the second opinion's and the challenger's searches when they
are asked (``ImageProcessor.times``, :class:`~drake_tracker.core.image_processor.
DecisionTimes`). The decision's share is its time over the update's, per case and
pooled over the cases (the sum of the decisions' times over the sum of the updates').

The cases are simulated here with the quick suite's image pacing (0.1 s) and replayed
through the offline tracker, one numba thread as the evaluation's workers run: the
demo's scenario (the arm in view, the default parameters' pacing) and three quick-suite
cases where the decision works hardest: bias steps (``s-full-arm/time-varying``, the
second opinion), a bias that walks at 6 deg/sqrt(s) (``s-full-arm/random-walk-6``, the
challenger searches beside the update) and a lasting occluder (``occlusion-lasting/
constant``), each shortened with its events kept (``shorten_scenario``).
"""

from __future__ import annotations

#: The quick-suite cases (sequence/bias) timed beside the demo's scenario.
CASES = ("s-full-arm/time-varying", "s-full-arm/random-walk-6", "occlusion-lasting/constant")


def _replay_times(run, params) -> dict:
    """Replays ``run`` with ``params``: its processors' :class:`DecisionTimes`, summed
    (``ReplayResult.decision_times``), with the decision's share and the replay's wall
    time."""
    from drake_tracker.io.replay import replay_run

    replay = replay_run(run, params)
    times = dict(replay.decision_times)
    return {**times, "decision_share": times["decision_s"] / times["update_s"],
            "replay_wall_s": replay.wall_time_s}


def bench_decision(duration_s: float) -> dict:
    """Per case (the demo's scenario as ``demo``, and :data:`CASES`), images observed,
    update and decision seconds and the decision's share, over the first ``duration_s``
    of each; ``pooled_decision_share`` over all of them."""
    import numba

    from drake_tracker.demo.run import DEFAULT_SCENARIO, render_what_the_tracker_reads
    from drake_tracker.evaluation.tasks import QUICK_IMAGE_INTERVAL_S, protocol_params
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario
    from drake_tracker.sim.scenario.timing import shorten_scenario

    cases, threads = {}, numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        params = TrackerParams()
        demo = render_what_the_tracker_reads(load_scenario(DEFAULT_SCENARIO), params)
        run = simulate_and_record(demo, duration_s=duration_s,
                                  image_stride=demo.camera.render_stride, validate=False)
        _replay_times(run, params)  # compiles the kernels: not timed
        cases["demo"] = _replay_times(run, params)
        for name in CASES:
            scenario = load_scenario(name)
            shorten_scenario(scenario, duration_s)
            run = simulate_and_record(scenario)
            cases[name] = _replay_times(run, protocol_params(
                run, "full_fusion", QUICK_IMAGE_INTERVAL_S, tracker_seed=scenario.seed))
    finally:
        numba.set_num_threads(threads)
    update_s = sum(c["update_s"] for c in cases.values())
    decision_s = sum(c["decision_s"] for c in cases.values())
    return {"duration_s": duration_s, "demo_scenario": DEFAULT_SCENARIO, "cases": cases,
            "pooled_decision_share": decision_s / update_s}


def format_decision(result: dict) -> str:
    """One line per case and the pooled share."""
    share = 100 * result["pooled_decision_share"]
    lines = [f"per-image decision beside the image update ({result['duration_s']:.0f} s "
             f"per case, offline tracker, 1 thread): pooled {share:.1f} % of the update"]
    for name, c in result["cases"].items():
        n = max(c["images"], 1)
        lines.append(f"  {name}: {c['images']} images, update {1e3 * c['update_s'] / n:.1f} "
                     f"ms, decision {1e3 * c['decision_s'] / n:.1f} ms per image "
                     f"({100 * c['decision_share']:.1f} %)")
    return "\n".join(lines)
