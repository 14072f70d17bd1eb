"""``teleop bridge --config FILE``: the simulated rig behind the Zenoh rig interface, as its own process.

The process a motor controller would be: it subscribes to the set-points on
``teleop/<instrument>/rig/setpoint`` and, at ``rig.rate_hz``, moves the simulated motor toward the
newest one and publishes a sample (encoder, load cell, applied set-point and the simulator's truth)
on ``teleop/<instrument>/rig/sample`` (:mod:`teleop.rig_wire`). Set-points older than
``rig.zenoh.timeout_ms`` are not followed: the motor holds where it is (a drive's own watchdog).
A slave with ``rig.type: zenoh`` (same instrument id, reachable endpoints) then runs exactly as with
the in-process rig. The rig is the one ``rig.type: simulated`` builds from the same file.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
from typing import Any

from teleop.clock import Clock, MonotonicClock, Pacer
from teleop.codec import next_seq
from teleop.config import Config
from teleop.errors import ConfigError
from teleop.rig_wire import RigSample, RigSetpoint

__all__ = ["RigBridge", "sample_of", "run_bridge"]

log = logging.getLogger("teleop.bridge")


def sample_of(state, seq: int, setpoint_seq: int) -> RigSample:
    """The RigSample of a single-tendon :class:`slave.rig.RigState` (truth when it has one)."""
    tr = state.truth
    truth = ((tr.T_in, tr.T_out, tr.x_in, tr.x_out, tr.elongation),) if tr is not None else ()
    return RigSample(seq, setpoint_seq, state.t, (state.x_in,), (state.T_in,), (state.x_in_cmd,), truth)


class RigBridge:
    """One rig served over the rig interface; :meth:`step` once per cycle, :meth:`run` paces it.

    Parameters
    ----------
    rig : a single-tendon rig (``step``, ``state``, ``set_load``)
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
        self.hold = float(rig.state.x_in_cmd)
        self.cycles = self.followed = self.held = 0
        self._seq = 0
        self._sp_seq = 0
        self._last: Any = None

    def step(self, now: float) -> None:
        """Follow the newest fresh set-point (else hold), step the rig one cycle, publish its sample."""
        rec = self.setpoints.latest()
        if rec is not None and self.setpoints.age(now) <= self.timeout:
            sp: RigSetpoint = rec.message
            if rec is not self._last and sp.tissue >= 0:
                self.rig.set_load(tissue=bool(sp.tissue))
            self._last = rec
            self.hold, self._sp_seq = float(sp.x_in_cmd[0]), sp.seq
            self.followed += 1
        else:
            self.hold = float(self.rig.state.truth.x_in) if self.rig.state.truth is not None else self.hold
            self.held += 1
        st = self.rig.step(self.hold, self.dt)
        self.samples.put(sample_of(st, self._seq, self._sp_seq))
        self._seq = next_seq(self._seq)
        self.cycles += 1

    def run(self, clock: Clock, *, max_duration: float | None = None) -> dict:
        """Pace :meth:`step` at ``rate_hz`` until ``max_duration`` [s] (or an interrupt); pacer stats."""
        pacer = Pacer(clock, self.rate_hz)
        t0 = clock.now()
        try:
            while max_duration is None or clock.now() - t0 < max_duration:
                self.step(pacer.wait())
        finally:
            stats = pacer.stats()
        return stats


def run_bridge(args: argparse.Namespace) -> int:
    """``teleop bridge``: serve the simulated rig of ``--config`` until stopped (module docstring)."""
    from slave.rigs import make_rig
    from teleop.config import load_config
    from teleop.keys import rig_key
    from teleop.recording import raise_on_sigterm
    from teleop.rig_wire import decode_rig, encode_rig
    from teleop.sides import open_session

    cfg: Config = load_config(args.config)
    if cfg.instrument.joints:
        raise ConfigError(f"{args.config}: `teleop bridge` serves a single-tendon rig so far (instrument.joints given)")
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
