"""Fitting (K, L/EA) to single-tendon recordings: recovery on self-generated data, held-out scoring."""
import numpy as np
import pytest

from estimator.offline.fit import fit_model, fit_single, predict, split_index
from estimator.online.distal import estimate_batch
from estimator.sheath import SheathModel

K_TRUE, C_TRUE = 0.45, 8e-5        # [-], L/EA [m/N]


def history(n=20000, dt=1e-3):
    """Proximal tension with reversals and minor loops, and a displacement [N], [m]."""
    t = np.arange(n) * dt
    T_in = (6 + 4 * np.sin(2 * np.pi * 0.25 * t) + 1.5 * np.sin(2 * np.pi * 1.3 * t + 1)
            + 0.4 * np.sin(2 * np.pi * 3.7 * t))
    x_in = 2e-3 * np.sin(2 * np.pi * 0.25 * t) + 1e-4 * T_in
    return t, T_in, x_in


def test_predict_profile_is_estimate_batch():
    t, T_in, x_in = history(3000)
    ref = estimate_batch(T_in, x_in, SheathModel(K_TRUE, C_TRUE), time=t, n_nodes=80, pretension=T_in[0])
    T_hat, x_hat = predict("profile", T_in, x_in, K_TRUE, C_TRUE, n_nodes=80)
    np.testing.assert_allclose(T_hat, ref.T_out, rtol=1e-12)
    np.testing.assert_allclose(x_hat, ref.x_out, rtol=1e-12, atol=1e-15)


def test_split_is_a_time_block():
    t = np.linspace(0.0, 10.0, 1001)
    k = split_index(t, 0.6)
    assert t[k - 1] < 6.0 <= t[k]
    with pytest.raises(ValueError, match="train_fraction"):
        split_index(t, 1.0)
    with pytest.raises(ValueError, match="fewer than 2 samples"):
        split_index(t[:3], 0.9)


@pytest.mark.parametrize("signals", ["both", "T_out", "x_out"])
def test_profile_fit_recovers_K_and_compliance(signals):
    t, T_in, x_in = history()
    T_out, x_out = predict("profile", T_in, x_in, K_TRUE, C_TRUE)
    kw = {"T_out": T_out if signals != "x_out" else None, "x_out": x_out if signals != "T_out" else None}
    res = fit_single(t, T_in, x_in, **kw)
    f = res.fits["profile"]
    assert f.K == pytest.approx(K_TRUE, rel=0.02)
    if signals == "T_out":
        assert f.compliance is None
    else:
        assert f.compliance == pytest.approx(C_TRUE, rel=0.02)
    for m in f.heldout.values():
        assert m.max_fs < 1e-3          # its own data: held-out error is numerical only
    assert res.n_train + res.n_heldout == t.size and res.split_time == pytest.approx(12.0, abs=1e-3)


def test_phase_fit_recovers_its_own_parameters():
    t, T_in, x_in = history()
    T_out, x_out = predict("phase", T_in, x_in, 0.7, 5e-5)
    f = fit_single(t, T_in, x_in, T_out=T_out, x_out=x_out).fits["phase"]
    assert f.K == pytest.approx(0.7, rel=0.02)
    assert f.compliance == pytest.approx(5e-5, rel=0.02)


def test_profile_memory_beats_phase_formulas_on_minor_loops():
    # truth = exact Coulomb memory; the paper's last-reversal rule cannot follow the minor loops
    t, T_in, x_in = history()
    T_out, x_out = predict("profile", T_in, x_in, 0.8, C_TRUE)
    res = fit_single(t, T_in, x_in, T_out=T_out, x_out=x_out)
    prof, phase = res.fits["profile"].heldout, res.fits["phase"].heldout
    assert phase["T_out"].max_fs > 0.05                     # a visible error for the paper's rule
    assert prof["T_out"].rmse < phase["T_out"].rmse / 100
    assert prof["x_out"].rmse < phase["x_out"].rmse / 100


def test_fit_needs_a_distal_signal():
    t, T_in, x_in = history(200)
    with pytest.raises(ValueError, match="T_out or x_out"):
        fit_model("profile", T_in, x_in, n_train=100)
    with pytest.raises(ValueError, match="constant on the training block"):
        fit_model("profile", T_in, x_in, T_out=np.ones_like(T_in), n_train=100)
    with pytest.raises(ValueError, match="estimator must be one of"):
        fit_model("magic", T_in, x_in, T_out=T_in, n_train=100)
