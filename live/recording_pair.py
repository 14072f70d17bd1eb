"""A KAIST recording played as an antagonistic pair, estimated by the pair axis's online estimator.

The KAIST robot (``sine_config_N.txt``, :mod:`study.kaist`) turns one motor that draws tendon a in and lets
tendon b out: x_in,a = +g c, x_in,b = -g c for the motor command c [rad]; the proximal load cells give T_a, T_b
[N]; an EM tracker measures the distal bending angle, the truth. The pulley radius r, g and the tendons'
compliances are not separately observable from these signals, so the rig speaks in units of r (r = 1):
x_in = (G c, -G c) with G = g / r, L/EA_j = 2 lam_j [rad/N] (as :func:`estimator.online.joint_batch.predict_pair_angle`).

:class:`RecordedPair` is the rig (:class:`slave.rig.Rig` of one joint, one recorded sample per step).
:func:`kaist_live` calibrates on command cycle 1 (as ``teleop analyze --kaist``), plays every sample through
the rig and the pair axis's :class:`estimator.online.joint.JointEstimator` (the seed pair model with the pair
coupling, J1-J5), and scores the live angle on cycle 2 beside the offline seed pair model
(:func:`estimator.offline.pair.fit_pair`) on the same cycles. The calibration of the live estimator is the same
six parameters fitted with the estimator itself as the model (``fit_pair(..., predict=predict_pair_angle)``).

The offline analysis's headline (the *extended* model its diagnosis chooses, a capstan joint model: the joint's
own friction and stiffness, docs/results/kaist.md) is not an online estimator: the live estimator leaves out
what the extension adds, and :func:`kaist_live` reports what that costs in degrees when given the analysis's
figure.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from estimator.offline.pair import PairParams, fit_pair
from estimator.online.joint import KAIST_PLAY, JointEstimator
from estimator.online.joint_batch import predict_pair_angle
from estimator.sheath import SheathModel
from slave.rig import InstrumentTruth, RigInputError, RigState
from study.kaist import KaistRecording, split

__all__ = ["RecordedPair", "kaist_live"]

N_NODES = 50          # profile elements per tendon, as the offline pair model


class RecordedPair:
    """A KAIST recording as one joint's tendon pair (module docstring); x_in in units of the pulley radius.

    Parameters
    ----------
    rec : KaistRecording
    G : float
        Motor-to-joint ratio g / r [-] (the calibration's).
    joint_name : str
    """

    def __init__(self, rec: KaistRecording, G: float, joint_name: str = "bend"):
        self.rec, self.G = rec, float(G)
        self.joint_names = (joint_name,)
        self.finished = False
        self._i = 0
        self._state = self._read(0, np.zeros((1, 2)))

    @property
    def state(self) -> RigState:
        return self._state

    def step(self, x_in_cmd: Any, dt: float) -> RigState:
        """The next recorded sample (the command is recorded in the state, the recording's motion is the one that
        happened). Raises RigInputError for ``dt`` not a finite number > 0."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise RigInputError(f"dt must be a finite time step > 0 s, got {dt!r}")
        n = len(self.rec)
        self._i = min(self._i + 1, n - 1)
        self.finished = self._i == n - 1
        self._state = self._read(self._i, np.asarray(x_in_cmd, dtype=float).reshape(1, 2))
        return self._state

    def _read(self, k: int, cmd: np.ndarray) -> RigState:
        r = self.rec
        x = self.G * float(r.command[k])
        none = np.zeros((1, 2))         # distal tensions and stretch are not measured on the KAIST robot
        truth = InstrumentTruth(theta=np.array([r.angle[k]]), torque=np.zeros(1), T_in=none, T_out=none, x_in=none,
                                x_out=none, elongation=none)
        return RigState(t=float(r.time[k]), x_in=np.array([[x, -x]]), T_in=np.array([[r.T_a[k], r.T_b[k]]]),
                        x_in_cmd=cmd, truth=truth)

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """The recorded load is the one that acted: nothing to switch."""

    def close(self) -> None:
        """Nothing to release; idempotent."""


def kaist_live(rec: KaistRecording, extended_deg: float | None = None) -> dict:
    """Live and offline distal-angle RMSE [deg] on the test cycles of ``rec`` (module docstring); with
    ``extended_deg`` (the offline analysis's extended model on the same cycles) the cost of leaving it out."""
    c1, c2, how = split(rec)
    n_train = c1.stop
    live_fit = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, n_train, N_NODES, predict=predict_pair_angle,
                        name="joint estimator")
    seed = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, n_train, N_NODES)
    p = PairParams(**live_fit.params)
    rig = RecordedPair(rec, p.G)
    models = [SheathModel(K=K, compliance=max(2.0 * lam, 1e-12)) for K, lam in ((p.K_a, p.lam_a), (p.K_b, p.lam_b))]
    est = JointEstimator(models[0], models[1], 1.0, n_nodes=N_NODES, pretension=(float(rec.T_a[0]), float(rec.T_b[0])),
                         play=KAIST_PLAY)
    offset = p.G * float(rec.command[0]) + p.theta0
    angle = np.empty(len(rec))
    st = rig.state
    for k in range(len(rec)):
        if k:
            st = rig.step(st.x_in, float(rec.time[k] - rec.time[k - 1]))
        s = est.step(float(st.T_in[0, 0]), float(st.x_in[0, 0]), float(st.T_in[0, 1]), float(st.x_in[0, 1]), st.t)
        angle[k] = s.angle + offset

    def deg(e: np.ndarray) -> float:
        return float(math.degrees(np.sqrt(np.mean(e ** 2))))
    out = {"config_deg": rec.config_deg, "split": how, "test_samples": int(c2.stop - c2.start),
           "live_rmse_deg": deg(angle[c2] - rec.angle[c2]),
           "live_batch_rmse_deg": deg(live_fit.prediction[c2] - rec.angle[c2]),
           "seed_offline_rmse_deg": deg(seed.prediction[c2] - rec.angle[c2])}
    if extended_deg is not None:
        out["extended_offline_rmse_deg"] = float(extended_deg)
        out["left_out_cost_deg"] = out["live_rmse_deg"] - float(extended_deg)
    return out
