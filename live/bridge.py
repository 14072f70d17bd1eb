"""``teleop bridge --config FILE``: the simulated rig behind the Zenoh rig interface, as its own process.

The process a motor controller would be (one tendon, or every tendon of a joint instrument): it subscribes to the
set-points on ``teleop/<instrument>/rig/setpoint`` and, at ``rig.rate_hz``, moves the simulated motor toward the newest
one and publishes a sample (encoder, load cell, applied set-point and the simulator's truth) on
``teleop/<instrument>/rig/sample`` (:mod:`teleop.wire.rig`). Set-points older than ``rig.zenoh.timeout_ms`` are not
followed: the motor holds where it is (a drive's own watchdog). A slave with ``rig.type: zenoh`` (same instrument id,
reachable endpoints) then runs exactly as with the in-process rig. The rig is the one ``rig.type: simulated`` builds
from the same file.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
from typing import Any

import numpy as np

from teleop.config.schema import Config
from teleop.timing.clock import Clock, MonotonicClock, Pacer
from teleop.wire.codec import next_seq
from teleop.wire.rig import RigSample, RigSetpoint

__all__ = ["RigBridge", "sample_of", "run_bridge"]

log = logging.getLogger("live.bridge")


def _flat(a) -> tuple[float, ...]:
    return tuple(float(v) for v in np.ravel(a))


def sample_of(state, seq: int, setpoint_seq: int) -> RigSample:
    """The RigSample of a rig's state: a :class:`slave.rig.RigState` (one tendon) or a
    :class:`slave.rig.RigState` (tendons joint 0 a, joint 0 b, ...), truth when it has one."""
    tr = state.truth
    truth: tuple = ()
    if tr is not None:
        cols = [_flat(getattr(tr, k)) for k in ("T_in", "T_out", "x_in", "x_out", "elongation")]
        truth = tuple(zip(*cols, strict=False))
    return RigSample(seq, setpoint_seq, state.t, _flat(state.x_in), _flat(state.T_in), _flat(state.x_in_cmd), truth)


class RigBridge:
    """One rig served over the rig interface; :meth:`step` once per cycle, :meth:`run` paces it.

    Parameters
    ----------
    rig : a rig of one tendon or a joint instrument (``step``, ``state``, ``set_load``)
    setpoints : latest-wins subscriber of RigSetpoint (``latest()``, ``age(now)``)
    samples : publisher of RigSample (``put``)
    rate_hz : float, the rig's cycle rate [Hz]
    timeout : float, set-points older than this are not followed [s]

    Attributes
    ----------
    cycles, followed, held : int
        Cycles run; cycles that followed a fresh set-point; cycles that held (none yet, or stale).
    """

    def __init__(self, rig, setpoints, samples, rate_hz: float, timeout: float):
        self.rig, self.setpoints, self.samples = rig, setpoints, samples
        self.rate_hz, self.timeout = float(rate_hz), float(timeout)
        self.dt = 1.0 / self.rate_hz
        self.shape = np.shape(rig.state.x_in_cmd)        # () for one tendon, (n_joints, 2) for an instrument
        self.hold: Any = self._shaped(_flat(rig.state.x_in_cmd))
        self.cycles = self.followed = self.held = 0
        self._seq = 0
        self._sp_seq = 0
        self._last: Any = None

    def _shaped(self, values: tuple[float, ...]):
        return float(values[0]) if self.shape == () else np.reshape(np.array(values, dtype=float), self.shape)

    def step(self, now: float) -> None:
        """Follow the newest fresh set-point (else hold), step the rig one cycle, publish its sample."""
        rec = self.setpoints.latest()
        if rec is not None and self.setpoints.age(now) <= self.timeout:
            sp: RigSetpoint = rec.message
            if rec is not self._last and sp.tissue >= 0:
                self.rig.set_load(tissue=bool(sp.tissue))
            self._last = rec
            self.hold, self._sp_seq = self._shaped(sp.x_in_cmd), sp.seq
            self.followed += 1
        else:
            tr = self.rig.state.truth                   # hold the motors where they are
            self.hold = self._shaped(_flat(tr.x_in)) if tr is not None else self.hold
            self.held += 1
        st = self.rig.step(self.hold, self.dt)
        self.samples.put(sample_of(st, self._seq, self._sp_seq))
        self._seq = next_seq(self._seq)
        self.cycles += 1

    def run(self, clock: Clock, *, max_duration: float | None = None) -> dict:
        """Pace :meth:`step` at ``rate_hz`` until ``max_duration`` [s] (or an interrupt); pacer stats."""
        pacer = Pacer(clock, self.rate_hz)
        t0 = clock.now()
        over = None if max_duration is None else (lambda: clock.now() - t0 >= max_duration)  # ends a long sleep
        try:
            while max_duration is None or clock.now() - t0 < max_duration:
                now = pacer.wait(over)
                if pacer.halted:
                    break
                self.step(now)
        finally:
            stats = pacer.stats()
        return stats


def run_bridge(args: argparse.Namespace) -> int:
    """``teleop bridge``: serve the simulated rig of ``--config`` until stopped (module docstring)."""
    from live.sides import open_session
    from slave.rigs import make_rig
    from teleop.config.load import load_config
    from teleop.recording.measured import raise_on_sigterm
    from teleop.wire.keys import rig_key
    from teleop.wire.rig import decode_rig, encode_rig

    cfg: Config = load_config(args.config)
    sim = dataclasses.replace(cfg, rig=dataclasses.replace(cfg.rig, type="simulated"))
    rig = make_rig(sim)
    ident = cfg.instrument.id
    clock = MonotonicClock()
    with raise_on_sigterm(), open_session(cfg, args, clock) as session:
        samples = session.publisher(rig_key(ident, "sample"), encoder=encode_rig)
        setpoints = session.subscriber(rig_key(ident, "setpoint"), RigSetpoint, decoder=decode_rig)
        bridge = RigBridge(rig, setpoints, samples, cfg.rig.rate_hz, cfg.rig.zenoh.timeout_ms * 1e-3)
        log.info("bridge: simulated rig of %s on %s", ident, rig_key(ident, "sample"))
        try:
            stats = bridge.run(clock, max_duration=args.max_duration)
        finally:
            log.info("bridge done: %d cycles, %d followed, %d held", bridge.cycles, bridge.followed, bridge.held)
    log.info("bridge pacing: %s", stats)
    return 0
