"""Smooth joint trajectories for the simulated sequences (positions as functions of time).

Every trajectory is a vectorised function ``positions(t) -> (T, n)`` of the robot's
joints, in radians (metres for prismatic joints), built from a ``TrajectoryConfig``:

* ``sinusoid``: joint k moves as ``home + A sin(2 pi t / T_k + k pi / 3)`` with
  ``T_k = period_s (1 + 0.17 k)``, so the joints are not in lock step;
* ``free``: a smooth random motion, per joint a sum of ``num_components`` sinusoids with
  seeded frequencies (0.04-0.15 Hz times ``speed_scale``), phases and weights, peak
  deviation ``amplitude_deg``;
* ``in-out-in``: the free motion plus a smooth excursion of one joint (cosine ramps)
  that takes the hand out of the camera view and back;
* ``static``: the home pose.

The world evaluates ``positions(t)`` exactly at every time it needs (no spline); it
checks the joint limits on samples ``sample_rate_hz`` per second over the run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.sim.scenario.config import TrajectoryConfig
from drake_tracker.sim.scenario.profiles import RobotProfile

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


def smooth_window(t: np.ndarray, start_s: float, duration_s: float, ramp_s: float) -> np.ndarray:
    """0 before ``start_s``, a cosine ramp up to 1 over ``ramp_s``, 1 for ``duration_s``,
    a cosine ramp back to 0. C1-continuous."""
    t = np.asarray(t, float)

    def ramp(x):
        if ramp_s <= 0:
            return (x >= 0).astype(float)
        y = np.clip(x / ramp_s, 0.0, 1.0)
        return 0.5 - 0.5 * np.cos(np.pi * y)

    up = ramp(t - start_s)
    down = ramp(t - (start_s + ramp_s + duration_s))
    return up - down


@dataclass
class JointTrajectory:
    """Positions of the robot's joints (``joint_names``) as a function of time."""

    joint_names: list[str]
    home: np.ndarray
    kind: str
    moved: np.ndarray  # indices of moved joints
    amplitude: float
    period_s: float
    # free motion: per moved joint, (M,) frequencies (Hz), phases, weights
    freqs: np.ndarray | None = None
    phases: np.ndarray | None = None
    weights: np.ndarray | None = None
    excursion_index: int = -1
    excursion: float = 0.0
    excursion_window: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: (period_s, moved) -> the sinusoids' periods and phases (see ``_sinusoids``).
    _sinusoid_terms: tuple | None = field(default=None, init=False, repr=False,
                                          compare=False)

    def positions(self, t: ArrayLike) -> np.ndarray:
        """Joint positions (T, n) at times ``t`` (s; a scalar or (T,)), in rad (m for prismatic
        joints), by ``kind`` as the module doc describes."""
        t = np.atleast_1d(np.asarray(t, float))
        q = np.empty((len(t), len(self.home)))
        q[:] = self.home
        terms = self._moved_terms(t)
        if terms is not None:
            moved, _, _, unique = self._sinusoids()
            if unique:
                q[:, moved] += terms
            else:  # a joint listed twice moves by both of its terms
                np.add.at(q, (slice(None), moved), terms)
        if self.kind == "in-out-in" and self.excursion_index >= 0:
            q[:, self.excursion_index] += self.excursion * smooth_window(
                t, *self.excursion_window)
        return q

    def position_at(self, t: float) -> np.ndarray:
        """(n,) positions at the single time ``t`` (s): the numbers of
        ``positions([t])[0]`` (the same terms), with a few numpy calls instead of a dozen
        (the world's encoders read it 1000 times a simulated second)."""
        moved, _, _, unique = self._sinusoids()
        if not unique or (self.kind == "in-out-in" and self.excursion_index >= 0):
            return self.positions(t)[0]
        q = np.array(self.home, float)
        terms = self._moved_terms(np.float64(t))
        if terms is not None:
            q[moved] += terms
        return q

    def _moved_terms(self, t: np.ndarray) -> np.ndarray | None:
        """The moved joints' motion, (T, k) at times ``t`` (T,), or (k,) at one time (a
        0-d array); None when no joint moves. The same operations for all k at once:
        ``sinusoid`` joint k: amplitude sin(2 pi t / T_k + phi_k); ``free`` and
        ``in-out-in`` joint k: amplitude sum_m w_km sin(2 pi f_km t + phi_km)."""
        if not len(self.moved):
            return None
        if self.kind == "sinusoid":
            _, periods, phases, _ = self._sinusoids()
            return self.amplitude * np.sin(2 * np.pi * t[..., None] / periods + phases)
        if self.kind in ("free", "in-out-in"):
            arg = 2 * np.pi * (t[..., None, None] * self.freqs) + self.phases
            return self.amplitude * np.einsum("...km,km->...k", np.sin(arg), self.weights)
        return None

    def _sinusoids(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """The moved joints, their periods ``period_s (1 + 0.17 k)`` and phases
        ``k pi / 3`` (k-th moved joint), and whether no joint is listed twice; kept
        while ``period_s`` and ``moved`` stay the same."""
        moved = np.asarray(self.moved, int)
        key = (self.period_s, moved.tobytes())
        if self._sinusoid_terms is None or self._sinusoid_terms[0] != key:
            k = np.arange(len(moved))
            self._sinusoid_terms = (key, moved.copy(), self.period_s * (1.0 + 0.17 * k),
                                    k * np.pi / 3, len(np.unique(moved)) == len(moved))
        return self._sinusoid_terms[1:]

    def velocities(self, t: ArrayLike, h: float = 1e-4) -> np.ndarray:
        """Central differences of ``positions`` (the functions are smooth)."""
        t = np.atleast_1d(np.asarray(t, float))
        return (self.positions(t + h) - self.positions(t - h)) / (2 * h)


def make_joint_trajectory(
    config: TrajectoryConfig,
    joint_names: list[str],
    profile: RobotProfile | None,
    seed: int,
) -> JointTrajectory:
    """The trajectory ``config`` describes for a robot with ``joint_names``."""
    home_deg = dict(profile.home_deg) if profile else {}
    home_deg.update(config.home_deg)
    home = np.array([np.radians(home_deg.get(n, 0.0)) for n in joint_names])
    moved_names = list(config.joints) or (profile.arm if profile else list(joint_names))
    for n in moved_names:
        if n not in joint_names:
            raise ValueError(f"trajectory.joints: joint '{n}' not in {joint_names}")
    moved = np.array([joint_names.index(n) for n in moved_names], int)
    traj = JointTrajectory(
        joint_names=list(joint_names), home=home, kind=config.kind, moved=moved,
        amplitude=np.radians(config.amplitude_deg), period_s=config.period_s,
    )
    if config.kind in ("free", "in-out-in"):
        rng = np.random.default_rng([seed, 0x7A1])
        M = config.num_components
        traj.freqs = config.speed_scale * rng.uniform(0.04, 0.15, (len(moved), M))
        traj.phases = rng.uniform(0, 2 * np.pi, (len(moved), M))
        w = rng.uniform(0.5, 1.0, (len(moved), M))
        traj.weights = w / w.sum(axis=1, keepdims=True)
    if config.kind == "in-out-in":
        if config.excursion_joint not in joint_names:
            raise ValueError(f"trajectory.excursion_joint: joint '{config.excursion_joint}' "
                             f"not in {joint_names}")
        traj.excursion_index = joint_names.index(config.excursion_joint)
        traj.excursion = np.radians(config.excursion_deg)
        traj.excursion_window = (config.excursion_start_s, config.excursion_duration_s,
                                 config.excursion_ramp_s)
    return traj


def check_within_limits(q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                        joint_names: list[str]) -> None:
    """Raises ValueError naming the first joint whose trajectory leaves its limits."""
    bad = np.nonzero((q.min(axis=0) < lower) | (q.max(axis=0) > upper))[0]
    if len(bad):
        j = bad[0]
        raise ValueError(
            f"trajectory: joint '{joint_names[j]}' ranges over "
            f"[{np.degrees(q[:, j].min()):.1f}, {np.degrees(q[:, j].max()):.1f}] deg, outside "
            f"its limits [{np.degrees(lower[j]):.1f}, {np.degrees(upper[j]):.1f}] deg")
