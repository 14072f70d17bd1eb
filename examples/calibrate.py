"""Calibrate a tendon from a pull into its joint limit (Phee et al. 2009, Sec. IV), proximal sensors only.

    python examples/calibrate.py

The simulated rig of the default configuration (a 1.5 m sheath with about 360 deg of bends, the distal
joint on a spring up to its limit) is pulled at ``calibration.speed`` until the load cell reads
``calibration.target_tension``. :func:`estimator.calibrate` finds the knee where the joint meets its
limit, reads M_e [m/N] as the slope of x_in over T_in beyond it and solves eq. (13) for the friction
exponent K. The result is compared with the rig's true values, then used to estimate the distal
tension of the same pull.
"""
from __future__ import annotations

import numpy as np

from estimator import DistalEstimator, calibrate
from slave.calibrate import route_wrap_shape
from slave.simulated import SimulatedRig
from teleop.config.load import load_config

DT = 1e-3       # rig step [s]


def main() -> int:
    cfg = load_config(None)                  # the defaults (configs/default.yaml spells them out)
    rig = SimulatedRig.from_config(cfg)
    rig.set_load(tissue=False)               # nothing but the joint spring and its limit at the tip
    x_cmd = rig.state.x_in
    x, T, T_out = [], [], []
    while rig.state.T_in < cfg.calibration.target_tension:
        x_cmd += cfg.calibration.speed * DT
        s = rig.step(x_cmd, DT)
        x.append(float(s.x_in))
        T.append(float(s.T_in))
        T_out.append(float(s.truth.T_out))
    geom = cfg.sheath.geometry()
    res = calibrate(np.asarray(x), np.asarray(T), L=geom.length, EA=cfg.sheath.EA, wrap_shape=route_wrap_shape(cfg))
    print(f"pull: {len(x)} samples, {1e3 * (x[-1] - x[0]):.2f} mm to {T[-1]:.1f} N; joint limit reached at "
          f"{res.knee_T_in:.2f} N")
    print(f"calibrated K   = {res.K:.4f}   (rig {rig.K:.4f}, error {100 * (res.K / rig.K - 1):+.2f} %)")
    print(f"calibrated M_e = {res.M_e * 1e6:.3f} um/N (rig {rig.M_e * 1e6:.3f} um/N, "
          f"error {100 * (res.M_e / rig.M_e - 1):+.2f} %)")
    est = DistalEstimator(res.model, tension_noise=res.tension_noise)
    hat = np.array([est.step(Ti, xi, k * DT).T_out for k, (Ti, xi) in enumerate(zip(T, x, strict=False))])
    err = hat - np.asarray(T_out)
    print(f"distal tension of the pull with the calibrated model: rms error {np.sqrt(np.mean(err ** 2)):.3f} N, "
          f"max {np.abs(err).max():.3f} N (true peak {max(T_out):.2f} N)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
