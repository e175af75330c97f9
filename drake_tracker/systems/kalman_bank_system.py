"""The joint Kalman bank as a Drake LeafSystem: the encoder-rate estimate."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import (
    BasicVector,
    Context,
    EventStatus,
    LeafSystem,
    ValueProducer,
)

from drake_tracker.core.filter.estimate import PoseReadout
from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.core.image_step import full_reading, make_bank_and_prior, robot_joint_indices
from drake_tracker.core.sensors.reading_gate import ReadingGate, is_new_stamp
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.systems.messages import BeliefCorrection

if TYPE_CHECKING:
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)


@dataclass
class KalmanBankState:
    """The bank system's bookkeeping, read from its discrete state ``bookkeeping``
    (:meth:`JointKalmanBankSystem.bookkeeping`; the belief is the group ``belief``).
    ``time_s``/``last_reading_s`` are None before the first reading; ``correction_id``
    is the latest delay-buffer correction adopted; ``gate`` the readings' time-stamp
    policy (silent: the delay buffer logs)."""

    gate: ReadingGate
    time_s: float | None = None
    last_reading_s: float | None = None
    correction_id: int = 0

    #: Where the vector holds the correction's id, and where the gate's numbers begin
    #: (after time_s and last_reading_s).
    CORRECTION_ID = 2
    GATE = slice(3, None)

    def to_vector(self) -> np.ndarray:
        """The numbers of the discrete state group (NaN for None)."""
        head = [np.nan if v is None else v for v in (self.time_s, self.last_reading_s)]
        return np.concatenate([head, [self.correction_id], self.gate.to_vector()])

    @staticmethod
    def from_vector(x: np.ndarray, params: TrackerParams,
                    joint_names: list[str]) -> KalmanBankState:
        """The state that :meth:`to_vector` gave ``x``."""
        time_s, last_reading_s, correction_id = x[:KalmanBankState.GATE.start].tolist()
        return KalmanBankState(
            ReadingGate.from_vector(x[KalmanBankState.GATE], params.timestamps, joint_names),
            None if np.isnan(time_s) else time_s,
            None if np.isnan(last_reading_s) else last_reading_s, int(correction_id))


class JointKalmanBankSystem(LeafSystem):
    """Filters every new encoder reading with the per-joint Kalman bank, and adopts the
    delay buffer's belief whenever the buffer applied an image (a periodic discrete
    update: all of its state is numbers).

    .. pydrake_system::

        name: JointKalmanBankSystem
        input_ports:
        - measured_position
        - measurement_time
        - correction
        output_ports:
        - belief
        - estimated_position
        - position_variance
        - bias
        - bias_variance
        - camera_offset
        - X_CE
        - X_WE
        - X_WC

    ``measured_position`` holds the robot joints' readings (``model.robot_joint_names``),
    ``measurement_time`` its stamp (s; a stamp that changed marks a new reading, which
    goes through the time-stamp policy of ``core/sensors/timestamps.py``). ``correction`` is the
    delay buffer's :class:`BeliefCorrection`. Outputs cover all of ``model.joint_names``
    (virtual joints included): ``belief`` is the (5, n) moment array flattened
    row-major; ``camera_offset`` the 6 virtual joints;
    ``X_CE`` the hand in the estimated camera frame, ``X_WE`` the hand and ``X_WC`` the
    estimated camera in the model's world (RigidTransform). Before the first reading the
    estimate is the model's zero configuration.

    Discrete state: ``belief``, the (5, n) moments, row-major (:meth:`belief`), and
    ``bookkeeping``, a :class:`KalmanBankState` as numbers (:meth:`bookkeeping`; the
    gate's through :meth:`ReadingGate.to_vector`). Readings the delay buffer skips are
    skipped here too (the buffer logs them).
    """

    def __init__(self, model: TrackerModel, params: TrackerParams, period_s: float,
                 offset_s: float = 0.0):
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"JointKalmanBankSystem: period_s must be > 0, got {period_s}")
        self._model = model
        self._params = params
        self._n = model.num_joints
        self._robot_n = len(model.robot_joint_names)
        self._robot_indices = robot_joint_indices(model)
        self._bank, _ = make_bank_and_prior(model, params, None)
        self._readout = PoseReadout(model)
        n = self._n
        self._belief = self.DeclareDiscreteState(np.zeros(5 * n))
        self._bookkeeping = self.DeclareDiscreteState(KalmanBankState(
            ReadingGate(params.timestamps, model.robot_joint_names, logger=None)).to_vector())
        self._reading_port = self.DeclareVectorInputPort("measured_position", self._robot_n)
        self._time_port = self.DeclareVectorInputPort("measurement_time", 1)
        self._correction_port = self.DeclareAbstractInputPort(
            "correction", AbstractValue.Make(BeliefCorrection()))
        deps = {self.discrete_state_ticket(self._belief)}
        self.DeclareVectorOutputPort("belief", 5 * n, self._calc_belief, deps)
        self.DeclareVectorOutputPort("estimated_position", n,
                                     lambda c, o: self._row(c, o, MEAN_A), deps)
        self.DeclareVectorOutputPort("position_variance", n,
                                     lambda c, o: self._row(c, o, VAR_A), deps)
        self.DeclareVectorOutputPort("bias", n, lambda c, o: self._row(c, o, MEAN_B), deps)
        self.DeclareVectorOutputPort("bias_variance", n,
                                     lambda c, o: self._row(c, o, VAR_B), deps)
        self.DeclareVectorOutputPort("camera_offset", 6, self._calc_offset, deps)
        # X_CE, X_WE and X_WC, computed together once per belief
        self._poses = self.DeclareCacheEntry("poses", ValueProducer(
            allocate=AbstractValue.Make((RigidTransform(),) * 3).Clone,
            calc=self._calc_poses), deps)
        self.DeclareAbstractOutputPort("X_CE", lambda: AbstractValue.Make(RigidTransform()),
                                       lambda c, o: self._calc_pose(c, o, 0), deps)
        self.DeclareAbstractOutputPort("X_WE", lambda: AbstractValue.Make(RigidTransform()),
                                       lambda c, o: self._calc_pose(c, o, 1), deps)
        self.DeclareAbstractOutputPort("X_WC", lambda: AbstractValue.Make(RigidTransform()),
                                       lambda c, o: self._calc_pose(c, o, 2), deps)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, offset_s, self._update)

    # ----------------------------------------------------------------- state access
    def belief(self, context: Context) -> np.ndarray:
        """The (5, n) belief in ``context`` (the model's zero configuration before the
        first reading)."""
        return context.get_discrete_state(self._belief).get_value().reshape(5, self._n)

    def bookkeeping(self, context: Context) -> KalmanBankState:
        """The :class:`KalmanBankState` that the discrete state ``bookkeeping`` holds in
        ``context`` (built from its numbers: changing it changes no state)."""
        return KalmanBankState.from_vector(
            context.get_discrete_state(self._bookkeeping).get_value(), self._params,
            self._model.robot_joint_names)

    def _update(self, context, discrete_state) -> EventStatus | None:
        x = context.get_discrete_state(self._bookkeeping).get_value()
        correction = self._correction_port.Eval(context)
        adopt = (correction.id > int(x[KalmanBankState.CORRECTION_ID])
                 and correction.belief is not None)
        raw = float(self._time_port.Eval(context)[0])
        new_reading = (self._params.use_joint_readings
                       and is_new_stamp(raw, ReadingGate.last_raw_stamp(x[KalmanBankState.GATE])))
        if not (adopt or new_reading):
            return EventStatus.DidNothing()  # Drake keeps the state as it is
        belief = self.belief(context).copy()
        s = self.bookkeeping(context)
        if adopt:
            belief = correction.belief.copy()
            s.time_s, s.last_reading_s = correction.time_s, correction.last_reading_time_s
            s.correction_id = correction.id
        if new_reading:
            reading = np.array(self._reading_port.Eval(context), float)
            belief = self._filter(s, s.gate.admit(raw, reading), reading, belief)
        discrete_state.get_mutable_vector(self._belief).SetFromVector(belief.ravel())
        discrete_state.get_mutable_vector(self._bookkeeping).SetFromVector(s.to_vector())
        return None

    def _filter(self, s: KalmanBankState, t: float | None, reading: np.ndarray,
                belief: np.ndarray) -> np.ndarray:
        """The belief after an admitted reading at ``t`` (None: rejected by the gate)."""
        if t is None:
            return belief
        if s.gate.restarted:  # the clock restarted: start again from this reading
            s.time_s = s.last_reading_s = None
        if s.last_reading_s is not None and t <= s.last_reading_s:
            return belief
        if s.time_s is None:
            _, belief = make_bank_and_prior(self._model, self._params, reading)
            s.time_s = t
        belief = self._bank.step_unchecked(belief, t - s.time_s,
                                           full_reading(self._model, reading,
                                                        self._robot_indices))
        s.time_s = s.last_reading_s = t
        return belief

    # ----------------------------------------------------------------- outputs
    def _calc_belief(self, context, output: BasicVector):
        output.SetFromVector(self.belief(context).ravel())

    def _row(self, context, output: BasicVector, row: int):
        output.SetFromVector(self.belief(context)[row])

    def _calc_offset(self, context, output: BasicVector):
        output.SetFromVector(self.belief(context)[MEAN_A, self._model.virtual_joint_indices])

    def _calc_poses(self, context, value):
        value.set_value(tuple(RigidTransform(X[0]) for X in
                              self._readout.poses(self.belief(context)[MEAN_A])))

    def _calc_pose(self, context, output, which: int):
        output.set_value(self._poses.Eval(context)[which])
