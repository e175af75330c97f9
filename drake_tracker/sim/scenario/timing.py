"""Shorter runs that keep a scenario's events (for quick evaluations).

:func:`shorten_scenario` compresses a scenario to ``duration_s``: the legacy events by
fixed fractions of the run (the hand leaves the view at 20 % for 40 %, with 10 % ramps;
the legacy box is in front from 25 % to 85 %; bias steps at most every 30 %), and every
other timed event (occluders' windows, ramps and waypoints, bias ramps and listed
steps) scaled by ``duration_s / scenario.duration_s``.
"""

from __future__ import annotations

from drake_tracker.sim.scenario.config import Scenario
from drake_tracker.sim.scenario.validation import require_positive


def shorten_scenario(scenario: Scenario, duration_s: float) -> Scenario:
    """Compresses ``scenario``'s events into ``duration_s`` (in place; returned). A
    duration at or above the scenario's own leaves it unchanged."""
    require_positive(duration_s, "duration_s")
    d = float(duration_s)
    if d >= scenario.duration_s:
        return scenario
    scale = d / scenario.duration_s
    t = scenario.trajectory
    t.excursion_start_s, t.excursion_ramp_s = 0.2 * d, 0.1 * d
    t.excursion_duration_s = 0.4 * d
    o = scenario.occluder
    o.start_s, o.end_s = 0.25 * d, 0.85 * d
    for occluder in scenario.occluders:
        occluder.enter_s *= scale
        occluder.leave_s *= scale
        occluder.ramp_s *= scale
        occluder.waypoint_times_s = [scale * w for w in occluder.waypoint_times_s]
    e = scenario.encoders
    e.step_period_s = min(e.step_period_s, 0.3 * d)
    e.step_transition_s = min(e.step_transition_s, 0.5 * e.step_period_s)
    e.ramp_start_s *= scale
    e.ramp_duration_s *= scale
    for profile in e.bias_profiles.values():
        profile.ramp_start_s *= scale
        profile.ramp_duration_s *= scale
        profile.step_times_s = [scale * s for s in profile.step_times_s]
        profile.step_transition_s *= scale
    scenario.duration_s = d
    return scenario
