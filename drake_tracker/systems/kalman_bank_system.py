"""The joint Kalman bank as a Drake LeafSystem: the encoder-rate estimate."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import (
    BasicVector,
    Context,
    EventStatus,
    InputPort,
    LeafSystem,
    OutputPort,
    ValueProducer,
)

from drake_tracker.core.filter.estimate import PoseReadout
from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B, VAR_A, VAR_B
from drake_tracker.core.filter.start import full_reading, initial_belief, new_bank
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.systems.messages import AdmittedReading, BeliefCorrection

if TYPE_CHECKING:
    from drake_tracker.core.resolved_params import ResolvedParams
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

#: The bank's vector outputs: name -> the row of the (5, n) belief it shows.
_ROWS = {"estimated_position": MEAN_A, "position_variance": VAR_A, "bias": MEAN_B,
         "bias_variance": VAR_B}
#: Its pose outputs, computed together once per belief.
_POSES = ("X_CE", "X_WE", "X_WC")


@dataclass
class KalmanBankState:
    """The bank's bookkeeping, the discrete state group ``bookkeeping`` as numbers:
    the belief's time and its latest reading's (None before the first reading), and
    the ids of the latest correction and reading it took from the delay buffer."""

    time_s: float | None = None
    last_reading_s: float | None = None
    correction_id: int = 0
    reading_id: int = 0

    def to_vector(self) -> np.ndarray:
        """The numbers of the discrete state group (NaN for None)."""
        return np.array((np.nan if self.time_s is None else self.time_s,
                         np.nan if self.last_reading_s is None else self.last_reading_s,
                         self.correction_id, self.reading_id), float)

    @staticmethod
    def from_vector(x: np.ndarray) -> KalmanBankState:
        """The state that :meth:`to_vector` gave ``x``."""
        time_s, last_reading_s, correction_id, reading_id = x.tolist()
        return KalmanBankState(None if time_s != time_s else time_s,  # NaN: None
                               None if last_reading_s != last_reading_s else last_reading_s,
                               int(correction_id), int(reading_id))


class JointKalmanBankSystem(LeafSystem):
    """Filters every reading the delay buffer admits with the per-joint Kalman bank, and
    adopts the buffer's belief whenever it applied an image (a periodic discrete update:
    all of its state is numbers).

    .. pydrake_system::

        name: JointKalmanBankSystem
        input_ports:
        - reading
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

    ``reading`` is the buffer's :class:`AdmittedReading` (the readings pass one gate, the
    buffer's), ``correction`` its :class:`BeliefCorrection`. Outputs cover all of
    ``model.joint_names`` (virtual joints included): ``belief`` is the (5, n) moments
    row-major, ``camera_offset`` the 6 virtual joints, ``X_CE`` the hand in the
    estimated camera frame, ``X_WE`` the hand and ``X_WC`` the estimated camera in the
    model's world. Before the first reading the estimate is the zero configuration.

    With several cameras in ``model`` (``RobotConfig.cameras``), each camera ``<name>``
    also has ``<name>_camera_offset`` (its six virtual joints), ``<name>_X_WC`` (its
    estimated frame in the model's world) and ``<name>_X_CE`` (the hand in that frame);
    ``camera_offset``, ``X_CE`` and ``X_WC`` are the first camera's.

    Discrete state: ``belief`` (:meth:`belief`) and ``bookkeeping`` (:meth:`bookkeeping`).
    """

    def __init__(self, *, model: TrackerModel, params: TrackerParams | ResolvedParams,
                 period_s: float, offset_s: float = 0.0) -> None:
        super().__init__()
        if not period_s > 0:
            raise ValueError(f"JointKalmanBankSystem: period_s must be > 0, got {period_s}")
        self._params = resolve_tracker_params(params, model)
        self._n = n = model.num_joints
        self._bank = new_bank(self._params)
        self._readout = PoseReadout(model)
        self._virtual = model.virtual_joint_indices
        self._belief = self.DeclareDiscreteState(np.zeros(5 * n))
        self._bookkeeping = self.DeclareDiscreteState(KalmanBankState().to_vector())
        self._reading = self.DeclareAbstractInputPort(
            "reading", AbstractValue.Make(AdmittedReading()))
        self._correction = self.DeclareAbstractInputPort(
            "correction", AbstractValue.Make(BeliefCorrection()))
        deps = {self.discrete_state_ticket(self._belief)}
        # plain ints: fastest
        self._groups = (int(self._belief), int(self._bookkeeping))
        self._outputs = {"belief": self.DeclareVectorOutputPort(
            "belief", 5 * n, lambda c, o: o.SetFromVector(self.belief(c).ravel()), deps)}
        for name, row in _ROWS.items():
            self._outputs[name] = self.DeclareVectorOutputPort(
                name, n, lambda c, o, row=row: o.SetFromVector(self.belief(c)[row]), deps)
        self._outputs["camera_offset"] = self.DeclareVectorOutputPort(
            "camera_offset", 6, self.CalcCameraOffset, deps)
        self._several_cameras = len(model.cameras) > 1
        self._poses = self.DeclareCacheEntry("poses", ValueProducer(
            allocate=AbstractValue.Make(((RigidTransform(),) * 3, {})).Clone,
            calc=self.CalcPoses), deps)
        for k, name in enumerate(_POSES):
            self._outputs[name] = self.DeclareAbstractOutputPort(
                name, lambda: AbstractValue.Make(RigidTransform()),
                lambda c, o, k=k: o.set_value(self._poses.Eval(c)[0][k]), deps)
        if self._several_cameras:
            self._declare_camera_outputs(model, deps)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, offset_s, self._update)

    def _declare_camera_outputs(self, model: TrackerModel, deps: set) -> None:
        """Each camera's ``<name>_camera_offset``, ``<name>_X_WC`` and ``<name>_X_CE``
        outputs."""
        for camera in model.cameras:
            indices = model.camera_joint_indices(camera.name)
            self._outputs[f"{camera.name}_camera_offset"] = self.DeclareVectorOutputPort(
                f"{camera.name}_camera_offset", 6,
                lambda c, o, k=indices: o.SetFromVector(self.belief(c)[MEAN_A, k]), deps)
        for name in model.camera_names:
            for k, kind in enumerate(("X_WC", "X_CE")):
                self._outputs[f"{name}_{kind}"] = self.DeclareAbstractOutputPort(
                    f"{name}_{kind}", lambda: AbstractValue.Make(RigidTransform()),
                    lambda c, o, name=name, k=k: o.set_value(
                        self._poses.Eval(c)[1][name][k]), deps)

    def get_reading_input_port(self) -> InputPort:
        """The ``reading`` input port."""
        return self._reading

    def get_correction_input_port(self) -> InputPort:
        """The ``correction`` input port."""
        return self._correction

    def get_output_port_by_name(self, name: str) -> OutputPort:
        """One of the estimate's output ports (see the port block)."""
        return self._outputs[name]

    def belief(self, context: Context) -> np.ndarray:
        """The (5, n) belief in ``context`` (zero configuration before the first reading)."""
        return context.get_discrete_state().get_value(self._groups[0]).reshape(5, self._n)

    def bookkeeping(self, context: Context) -> KalmanBankState:
        """The :class:`KalmanBankState` in ``context`` (a copy: changing it changes no state)."""
        return KalmanBankState.from_vector(
            context.get_discrete_state().get_value(self._groups[1]))

    def _update(self, context: Context, discrete_state) -> EventStatus | None:
        # ``discrete_state`` holds a copy of the state (Drake's, for this update): its
        # groups are changed in place, through views, with no message rebuilt per reading.
        belief_group, book_group = self._groups
        book = discrete_state.get_mutable_value(book_group)
        time_s, last_reading_s, correction_id, reading_id = book.tolist()  # NaN: None
        reading = self._reading.EvalAbstract(context).get_value()  # Eval's value, cheaper
        adopt = False
        if reading.correction_id is None or reading.correction_id > correction_id:
            # The buffer tells the id of its latest correction with each reading: the
            # correction port is read only when there is a new one (or no word of it).
            correction = self._correction.Eval(context)
            adopt = correction.id > correction_id and correction.belief is not None
        new_reading = self._params.use_joint_readings and reading.id > reading_id
        if not (adopt or new_reading):
            return EventStatus.DidNothing()  # Drake keeps the state as it is
        belief = discrete_state.get_mutable_value(belief_group).reshape(5, self._n)  # a view
        if adopt:
            belief[:] = correction.belief
            time_s, last_reading_s = correction.time_s, correction.last_reading_time_s
            correction_id = correction.id
        if new_reading:
            reading_id = reading.id
            time_s, last_reading_s = self._filter(reading, time_s, last_reading_s, belief)
        # (item by item: a slice set from a tuple costs twice as much)
        book[0], book[1], book[2], book[3] = time_s, last_reading_s, correction_id, reading_id
        return None

    def _filter(self, reading: AdmittedReading, time_s: float, last_reading_s: float,
                belief: np.ndarray) -> tuple[float, float]:
        """Filters an admitted reading into ``belief`` in place (eqs. 3-5 of
        ``docs/method.md``); returns the belief's time and its latest reading's (NaN:
        none), as :class:`KalmanBankState` holds them."""
        t = reading.time_s
        if reading.restarted:  # the clock restarted: start again from this reading
            time_s = last_reading_s = np.nan
        if t <= last_reading_s:  # False for NaN
            return time_s, last_reading_s  # the adopted correction holds it already
        if time_s != time_s:  # NaN: no belief yet
            belief[:], time_s = initial_belief(self._params, reading.values), t
        self._bank.step_in_place(
            belief, t - time_s, full_reading(self._params, reading.values))
        return t, t

    def CalcCameraOffset(self, context: Context, output: BasicVector) -> None:
        """The six virtual camera joints' angles."""
        output.SetFromVector(self.belief(context)[MEAN_A, self._virtual])

    def CalcPoses(self, context: Context, value: AbstractValue) -> None:
        """X_CE, X_WE and X_WC of the belief's mean angles and, with several cameras,
        each camera's estimated frame in the world and the hand in it (name -> (X_WC,
        X_CE)), from one kinematics call."""
        q = self.belief(context)[MEAN_A]
        X_WB = self._readout.body_poses(q)
        poses = tuple(RigidTransform(X[0]) for X in self._readout.poses(q, X_WB))
        cameras = {}
        if self._several_cameras:
            X_WE = poses[1]
            for name, X_WC in self._readout.camera_poses(X_WB).items():
                X_WC = RigidTransform(X_WC[0])
                cameras[name] = (X_WC, X_WC.InvertAndCompose(X_WE))
        value.set_value((poses, cameras))
