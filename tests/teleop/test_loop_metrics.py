"""Chatter finds a 300 Hz burst and not a hand's motion; transparency against the scaled truth."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.errors import DataError
from teleop.timing.loop_metrics import (
    CHATTER_LIMITS,
    TRANSPARENCY_LIMIT_FS,
    chatter,
    chatter_checks,
    loop_metrics,
    transparency_checks,
)


def test_a_burst_is_found_where_it_is_and_a_slow_motion_is_quiet():
    t = np.arange(0.0, 4.0, 1e-3)
    hand = 0.005 * np.sin(2 * np.pi * 0.5 * t) + 0.002 * np.clip(t - 2, 0, None)     # slow, with a corner
    rms, worst, _ = chatter(t, hand)
    assert worst < 0.25 * CHATTER_LIMITS["x_in_cmd_m"]
    burst = np.where((t > 1.0) & (t < 1.5), 3e-4 * np.sign(np.sin(2 * np.pi * 300 * t)), 0.0)
    rms, worst, at = chatter(t, hand + burst)
    assert worst > 2e-4 and 0.95 <= at <= 1.45 and rms < worst
    with pytest.raises(DataError, match="1-D of one length"):
        chatter(t, hand[:-1])


def test_loop_metrics_per_experiment_and_checks():
    n = 3000
    t = 100.0 + np.arange(n) * 1e-3
    T_out = 5.0 + 5.0 * np.sin(2 * np.pi * 0.5 * (t - 100))
    marker = np.where(np.arange(n) < 1500, 1, 2)
    slave = {"t_node": t, "T_out": T_out, "marker": marker, "cmd_seq": np.arange(n)}
    force = -0.2 * T_out + 0.01                                   # 0.01 N off everywhere
    force[2000:2100] += 0.5 * np.sign(np.sin(2 * np.pi * 250 * t[2000:2100]))   # chatter in experiment 2
    master = {"time": t, "x_in": 1e-3 * np.sin(t), "force": force, "cmd_seq": np.arange(n), "state": np.full(n, 3)}
    m = loop_metrics(master, slave, 0.2, {1: "paper", 2: "minor"})
    assert m["paper"]["transparency"]["force_error_max_fs"] == pytest.approx(0.01 / 2.0, rel=0.02)
    assert m["minor"]["chatter"]["force_worst_N"] > CHATTER_LIMITS["force_N"]
    ok = chatter_checks(m)
    assert [v for k, v in sorted(ok.items())] == [False, True]     # minor fails, paper passes
    tr = transparency_checks(m)
    assert all(tr.values()) and all(f"{TRANSPARENCY_LIMIT_FS:g} FS" in k for k in tr)
    m["paper"]["transparency"]["force_error_rms_fs"] = float("nan")    # not measured: fails
    assert transparency_checks(m, limit=0.3) == {"paper: transparency rms < 0.3 FS": False,
                                                 "minor: transparency rms < 0.3 FS": True}
    with pytest.raises(DataError, match="slave.csv lacks column"):
        loop_metrics(master, {k: v for k, v in slave.items() if k != "T_out"}, 0.2, {1: "paper"})


def test_the_transparency_shares_find_where_the_error_is_made():
    """An estimate 3 % high, a 20 ms late rendering and a passivity cut of half the force for 0.4 s: each
    share finds its own effect and nothing of the others'."""
    n, s = 4000, 0.2
    t = 50.0 + np.arange(n) * 1e-3
    T_out = 4.0 + 4.0 * np.sin(2 * np.pi * 0.5 * (t - 50))
    T_hat = 1.03 * T_out
    slave = {"t_node": t, "T_out": T_out, "T_out_hat": T_hat, "marker": np.ones(n), "cmd_seq": np.arange(n)}
    force_cmd = -s * np.interp(t - 0.020, t, T_hat)
    force = force_cmd.copy()
    cut = (t > 51.0) & (t < 51.4)
    force[cut] *= 0.5
    master = {"time": t, "x_in": np.zeros(n), "force": force, "force_cmd": force_cmd, "cmd_seq": np.arange(n),
              "state": np.full(n, 3)}
    tr = loop_metrics(master, slave, s, {1: "paper"})["paper"]["transparency"]
    sh, fs = tr["shares_rms_fs"], tr["full_scale_N"]
    rms = lambda e: float(np.sqrt(np.mean(e * e)) / fs)       # noqa: E731
    assert sh["estimate"] == pytest.approx(rms(s * 0.03 * T_out), rel=1e-6)
    assert sh["loop"] == pytest.approx(rms(force_cmd + s * T_hat), rel=1e-6) and 0.01 < sh["loop"] < 0.05
    assert sh["passivity"] == pytest.approx(rms(np.where(cut, 0.5 * force_cmd, 0.0)), rel=1e-6)
    del master["force_cmd"]                             # without the mapped force: no shares
    assert "shares_rms_fs" not in loop_metrics(master, slave, s, {1: "paper"})["paper"]["transparency"]
