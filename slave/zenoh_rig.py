"""A rig behind Zenoh: the slave sends motor set-points and reads load-cell and encoder samples.

``rig.type: zenoh``. Whatever drives the motors - a motor controller running zenoh-pico, or
``teleop bridge`` running the simulated rig as its own process - subscribes to the set-points on
``teleop/<instrument>/rig/setpoint`` and publishes one sample per cycle on
``teleop/<instrument>/rig/sample`` (byte format: :mod:`teleop.wire.rig`). :meth:`ZenohRig.step`
publishes the new set-point and returns the newest sample received (one cycle behind, as a real
drive's sensors are), time-stamped on the slave's clock from the start (the two loops are not
in lock step: a sample may be read twice, ``repeats`` counts it, and the slave's time stays strictly
increasing); the slave node's watchdogs and calibration see it as any other :class:`slave.rig.Rig`. A sample older than
``rig.zenoh.timeout_ms`` is counted (``stale``), logged at a limited rate and flagged (``RigState.fault``): the
slave holds its motors and goes SAFE on it (:func:`slave.rig.sensor_fault`); the rig side holds its motors when
the set-points stop (the bridge does).

:class:`ZenohRig` is the single tendon (n = 1), :class:`ZenohInstrument` a joint instrument (n = 2 per
joint, in the order joint 0 a, joint 0 b, joint 1 a, ...); the samples' truth, when present, gives
the joint angle theta = x_out,a / r and torque r (T_out,a - T_out,b) of each joint.
"""
from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from slave.rig import InstrumentTruth, RigInputError, RigState, RigTruth
from teleop.config.schema import Config
from teleop.errors import TransportError
from teleop.session.entity import RateLimitedLog
from teleop.timing.clock import MonotonicClock
from teleop.wire.codec import next_seq
from teleop.wire.keys import rig_key
from teleop.wire.rig import RigSample, RigSetpoint, decode_rig, encode_rig

__all__ = ["ZenohRig", "ZenohInstrument", "state_from_sample", "instrument_state_from_sample"]

log = logging.getLogger("teleop.slave")
_NO_PROFILE = np.zeros(0)
_NO_PROFILE.flags.writeable = False


def state_from_sample(s: RigSample, t: float | None = None) -> RigState:
    """The :class:`RigState` of tendon 0 of a sample (truth when the sample carries it), at time ``t``
    [s] (default: the sample's own time stamp)."""
    truth = None
    if s.truth:
        T_in, T_out, x_in, x_out, e = s.truth[0]
        truth = RigTruth(T_in=T_in, T_out=T_out, x_in=x_in, x_out=x_out, elongation=e, profile=_NO_PROFILE)
    return RigState(t=s.t if t is None else t, x_in=s.x_in[0], T_in=s.T_in[0], x_in_cmd=s.x_in_cmd[0], truth=truth)


def instrument_state_from_sample(s: RigSample, r: np.ndarray, t: float | None = None) -> RigState:
    """The :class:`RigState` of a sample of ``2 n_joints`` tendons; ``r`` [m] the pulley radii,
    shape (n_joints,) (truth: theta = x_out,a / r, torque = r (T_out,a - T_out,b))."""
    nj = len(r)
    if len(s.x_in) != 2 * nj:
        raise RigInputError(f"rig sample of {len(s.x_in)} tendons for an instrument of {nj} joints (2 each)")
    shape = (nj, 2)
    truth = None
    if s.truth:
        a = np.asarray(s.truth, dtype=float).reshape(nj, 2, 5)
        T_out, x_out = a[..., 1], a[..., 3]
        truth = InstrumentTruth(theta=x_out[:, 0] / r, torque=r * (T_out[:, 0] - T_out[:, 1]), T_in=a[..., 0],
                                T_out=T_out, x_in=a[..., 2], x_out=x_out, elongation=a[..., 4])
    return RigState(t=s.t if t is None else t, x_in=np.reshape(s.x_in, shape), T_in=np.reshape(s.T_in, shape),
                           x_in_cmd=np.reshape(s.x_in_cmd, shape), truth=truth)


class _ZenohLink:
    """Set-points out, samples in (module docstring); subclasses turn samples into states."""

    def __init__(self, session, cfg: Config):
        ident = cfg.instrument.id
        z = cfg.rig.zenoh
        self.clock = getattr(session, "clock", None) or MonotonicClock()
        self.timeout = z.timeout_ms * 1e-3
        self._pub = session.publisher(rig_key(ident, "setpoint"), encoder=encode_rig)
        self._sub = session.subscriber(rig_key(ident, "sample"), RigSample, decoder=decode_rig)
        self._seq = 0
        self._tissue = -1
        self.stale = self.repeats = 0
        self._log = RateLimitedLog(log, 1.0, self.clock)
        if not self._sub.wait(1, z.wait_s):
            raise TransportError(f"rig.type zenoh: no sample on {rig_key(ident, 'sample')} within {z.wait_s:g} s "
                                 f"(is `teleop bridge` or the motor controller running and reachable?)")
        self._t0 = self.clock.now()
        self._seen = self._sub.latest()
        self._state = self._convert(self._seen.message, 0.0)

    def _convert(self, sample: RigSample, t: float):
        raise NotImplementedError

    @property
    def state(self):
        """The newest sample as a state."""
        return self._state

    def _exchange(self, x_in_cmd: tuple[float, ...]):
        """Publish the set-points; the newest sample as a state on the slave's clock (module docstring)."""
        self._pub.put(RigSetpoint(self._seq, self.clock.now(), x_in_cmd, self._tissue))
        self._seq = next_seq(self._seq)
        now = self.clock.now()
        rec = self._sub.latest()
        age = self._sub.age(now)
        fault = None
        if age > self.timeout:
            self.stale += 1
            fault = f"rig sample {1e3 * age:.1f} ms old (rig.zenoh.timeout_ms {self.timeout * 1e3:g})"
            self._log.warning("%s", fault)
        self.repeats += rec is self._seen
        self._seen = rec
        state = self._convert(rec.message, max(now - self._t0, self._state.t + 1e-9))
        self._state = state if fault is None else dataclasses.replace(state, fault=fault)
        return self._state

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """Tissue contact of a simulated rig behind the bridge (sent with the next set-points).

        Raises
        ------
        RigInputError (ValueError)
            ``force`` given (a distal set force is not part of the rig interface).
        """
        if force is not None:
            raise RigInputError("rig.type zenoh: a distal set force cannot be set through the rig interface")
        if tissue is not None:
            self._tissue = int(bool(tissue))

    def close(self) -> None:
        """Undeclare the set-point publisher and the sample subscriber; idempotent."""
        for ent in (self._pub, self._sub):
            try:
                ent.close()
            except TransportError:  # pragma: no cover - the session went first
                pass


class ZenohRig(_ZenohLink):
    """The ``zenoh`` rig of one tendon (module docstring).

    Parameters
    ----------
    session : teleop.session.transport.Session
        The slave's session (its endpoints reach the rig).
    cfg : Config
        ``instrument.id`` (keys), ``rig.zenoh`` (timeout_ms, wait_s).

    Attributes
    ----------
    stale : int
        Steps that returned a sample older than ``rig.zenoh.timeout_ms``.
    repeats : int
        Steps that returned the same sample as the step before.

    Raises
    ------
    TransportError
        No sample within ``rig.zenoh.wait_s`` of starting (the message names the key).
    """

    def _convert(self, sample: RigSample, t: float) -> RigState:
        return state_from_sample(sample, t)

    def step(self, x_in_cmd: float, dt: float) -> RigState:
        """Publish the set-point ``x_in_cmd`` [m]; return the newest sample (``dt`` is the rig's own business).

        Raises
        ------
        RigInputError (ValueError)
            ``x_in_cmd`` not a finite number.
        """
        try:
            cmd = float(x_in_cmd)
        except (TypeError, ValueError):
            raise RigInputError(f"x_in_cmd must be a number, got {x_in_cmd!r}") from None
        if not math.isfinite(cmd):
            raise RigInputError(f"x_in_cmd must be a finite displacement in metres, got {x_in_cmd!r}")
        return self._exchange((cmd,))


class ZenohInstrument(_ZenohLink):
    """The ``zenoh`` rig of a joint instrument: two tendons per joint (module docstring).

    Parameters
    ----------
    session, cfg : as :class:`ZenohRig`; ``instrument.joints`` gives the names and pulley radii.
    """

    def __init__(self, session, cfg: Config):
        self.joint_names = tuple(j.name for j in cfg.instrument.joints)
        self._r = np.array([j.pulley_radius for j in cfg.instrument.joints], dtype=float)
        super().__init__(session, cfg)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def _convert(self, sample: RigSample, t: float) -> RigState:
        return instrument_state_from_sample(sample, self._r, t)

    def step(self, x_in_cmd, dt: float) -> RigState:
        """Publish every motor's set-point (``x_in_cmd`` [m], shape (n_joints, 2)); the newest sample.

        Raises
        ------
        RigInputError (ValueError)
            Another shape or a non-finite value.
        """
        try:
            cmd = np.array(x_in_cmd, dtype=np.float64)
        except (TypeError, ValueError):
            raise RigInputError(f"x_in_cmd must be numbers of shape ({self.n_joints}, 2)") from None
        if cmd.shape != (self.n_joints, 2) or not np.all(np.isfinite(cmd)):
            raise RigInputError(f"x_in_cmd must be finite, shape ({self.n_joints}, 2) [joint, tendon a/b], got "
                                f"{cmd.tolist()}")
        return self._exchange(tuple(float(v) for v in cmd.ravel()))
