"""The joint Kalman bank as a Drake LeafSystem: the encoder-rate estimate."""

from __future__ import annotations

import logging

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_tracker.core.kalman import MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.core.pipeline import PoseReadout, full_reading, make_bank_and_prior
from drake_tracker.core.timestamps import ReadingGate
from drake_tracker.params import TrackerParams
from drake_tracker.systems.messages import BeliefCorrection

log = logging.getLogger(__name__)


class JointKalmanBankSystem(LeafSystem):
    """Filters every new encoder reading with the per-joint Kalman bank (periodic discrete
    update), and adopts the delay buffer's belief whenever the buffer applied an image.

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
    goes through the time-stamp policy of ``core/timestamps.py``). ``correction`` is the
    delay buffer's :class:`BeliefCorrection`. Outputs cover all of ``model.joint_names``
    (virtual joints included): ``belief`` is the (5, n) moment array flattened
    row-major; ``camera_offset`` the 6 virtual joints;
    ``X_CE`` the hand in the estimated camera frame, ``X_WE`` the hand and ``X_WC`` the
    estimated camera in the model's world (RigidTransform). Before the first reading the
    estimate is the model's zero configuration.

    Discrete state: [belief (5n), belief time, last reading time, correction id,
    started flag]; abstract state: the readings' :class:`ReadingGate`. Readings the
    delay buffer skips are skipped here too (the buffer logs them).
    """

    def __init__(self, model, params: TrackerParams, period_s: float, offset_s: float = 0.0):
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"JointKalmanBankSystem: period_s must be > 0, got {period_s}")
        self._model = model
        self._params = params
        self._n = model.num_joints
        self._robot_n = len(model.robot_joint_names)
        self._bank, _ = make_bank_and_prior(model, params, None)
        self._readout = PoseReadout(model)
        n = self._n
        x0 = np.zeros(5 * n + 4)
        x0[5 * n] = np.nan
        x0[5 * n + 1] = -np.inf
        self._state = self.DeclareDiscreteState(x0)
        self._gate = self.DeclareAbstractState(AbstractValue.Make(
            ReadingGate(params.timestamps, model.robot_joint_names, logger=None)))
        self.DeclareVectorInputPort("measured_position", self._robot_n)
        self.DeclareVectorInputPort("measurement_time", 1)
        self.DeclareAbstractInputPort("correction", AbstractValue.Make(BeliefCorrection()))
        deps = {self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort("belief", 5 * n, self._calc_belief, deps)
        self.DeclareVectorOutputPort("estimated_position", n,
                                     lambda c, o: self._row(c, o, MEAN_A), deps)
        self.DeclareVectorOutputPort("position_variance", n,
                                     lambda c, o: self._row(c, o, VAR_A), deps)
        self.DeclareVectorOutputPort("bias", n, lambda c, o: self._row(c, o, MEAN_B), deps)
        self.DeclareVectorOutputPort("bias_variance", n,
                                     lambda c, o: self._row(c, o, VAR_B), deps)
        self.DeclareVectorOutputPort("camera_offset", 6, self._calc_offset, deps)
        self.DeclareAbstractOutputPort("X_CE", lambda: AbstractValue.Make(RigidTransform()),
                                       lambda c, o: self._calc_pose(c, o, 0), deps)
        self.DeclareAbstractOutputPort("X_WE", lambda: AbstractValue.Make(RigidTransform()),
                                       lambda c, o: self._calc_pose(c, o, 1), deps)
        self.DeclareAbstractOutputPort("X_WC", lambda: AbstractValue.Make(RigidTransform()),
                                       lambda c, o: self._calc_pose(c, o, 2), deps)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, offset_s, self._update)

    # ----------------------------------------------------------------- state access
    def _unpack(self, context):
        x = context.get_discrete_state(self._state).get_value()
        n = self._n
        return (x[:5 * n].reshape(5, n), x[5 * n], x[5 * n + 1], int(x[5 * n + 2]),
                bool(x[5 * n + 3]))

    def _pack(self, belief, time_s, last_reading_s, correction_id, started):
        return np.concatenate([np.asarray(belief, float).ravel(),
                               [time_s, last_reading_s, correction_id, float(started)]])

    def _update(self, context, state):
        belief, time_s, last_reading, correction_id, started = self._unpack(context)
        belief = belief.copy()
        correction = self.get_input_port(2).Eval(context)
        if correction.id > correction_id and correction.belief is not None:
            belief = correction.belief.copy()
            time_s = correction.time_s
            last_reading = correction.last_reading_time_s
            correction_id = correction.id
            started = True
        raw = float(self.get_input_port(1).Eval(context)[0])
        gate: ReadingGate = state.get_mutable_abstract_state(self._gate).get_value()
        if self._params.use_joint_readings and gate.is_new(raw):
            reading = np.array(self.get_input_port(0).Eval(context), float)
            t = gate.admit(raw, reading)
            if t is not None and gate.restarted:  # restart from this reading
                started, last_reading = False, -np.inf
            if t is not None and t > last_reading:
                if not started:
                    _, belief = make_bank_and_prior(self._model, self._params, reading)
                    time_s, started = t, True
                belief = self._bank.step_unchecked(belief, t - time_s,
                                                   full_reading(self._model, reading))
                time_s = t
                last_reading = t
        state.get_mutable_discrete_state(self._state).SetFromVector(
            self._pack(belief, time_s, last_reading, correction_id, started))
        state.get_mutable_abstract_state(self._gate).set_value(gate)

    # ----------------------------------------------------------------- outputs
    def _calc_belief(self, context, output: BasicVector):
        output.SetFromVector(self._unpack(context)[0].ravel())

    def _row(self, context, output: BasicVector, row: int):
        output.SetFromVector(self._unpack(context)[0][row])

    def _calc_offset(self, context, output: BasicVector):
        output.SetFromVector(self._unpack(context)[0][MEAN_A, self._model.virtual_joint_indices])

    def _calc_pose(self, context, output, which: int):
        X = self._readout.poses(self._unpack(context)[0][MEAN_A])[which][0]
        output.set_value(RigidTransform(X))
