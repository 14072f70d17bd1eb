"""The seed paper's closed forms, cross-checked against the profile-memory estimator."""
import math

import numpy as np
import pytest

from estimator import capstan
from estimator.online.distal import estimate_batch
from estimator.phase import Phase
from estimator.sheath import SheathModel

K, C = 0.63, 1.0e-4  # friction exponent [-], L/EA [m/N]
MODEL = SheathModel(K=K, compliance=C)


def ramp(*points, n=4000):
    return np.concatenate([np.linspace(a, b, n)[1:] if i else np.linspace(a, b, n)
                           for i, (a, b) in enumerate(zip(points[:-1], points[1:], strict=False))])


def test_pull_and_release_ratios():
    assert capstan.t_out_pull(10.0, K) == pytest.approx(10 * math.exp(-K))
    assert capstan.t_out_release(np.array([1.0, 2.0]), K) == pytest.approx(np.array([1, 2]) * math.exp(K))


def test_M_e_and_newton_inverse_round_trip():
    for K_true in (0.05, 0.3, 0.63, 1.26, 3.0):
        m = capstan.M_e(K_true, 1.5, 15000.0)
        assert capstan.K_from_M_e(m, 1.5, 15000.0) == pytest.approx(K_true, rel=1e-8)


@pytest.mark.parametrize("ratio,word", [(1.2, "more compliant"), (0.0, "no positive stretch"), (-0.5, "no positive")])
def test_K_from_M_e_out_of_domain_says_why(ratio, word):
    with pytest.raises(ValueError, match=word):
        capstan.K_from_M_e(ratio * 1.5 / 15000.0, 1.5, 15000.0)


def test_profile_estimator_reproduces_paper_phases_on_single_reversals():
    """Pull to 20 N, release to 5 N, pull to 20 N: exact agreement away from phase boundaries."""
    T_in = ramp(0, 20, 5, 20)
    est = estimate_batch(T_in, np.zeros_like(T_in), MODEL, n_nodes=400)
    T_out, e, _ = capstan.phase_formula_batch(T_in, K, C, deadband=1e-6)
    assert np.max(np.abs(est.T_out - T_out)) < 1e-3 * 20
    assert np.max(np.abs(est.elongation - e)) < 2e-3 * capstan.elongation_release(20, K, C)


def test_transition_band_is_2K_wide():
    T_in = ramp(0, 20, 0)
    est = estimate_batch(T_in, np.zeros_like(T_in), MODEL, n_nodes=200)
    rel = T_in[4000:]
    held = est.T_out[4000:]
    inside = rel > 20 * math.exp(-2 * K) * 1.01
    assert np.allclose(held[inside], 20 * math.exp(-K), rtol=1e-9)
    below = rel < 20 * math.exp(-2 * K) * 0.99
    assert np.allclose(held[below], rel[below] * math.exp(K), rtol=1e-9)


def test_transition_elongations_meet_the_branches():
    T0 = 20.0
    lo = T0 * math.exp(-2 * K)
    assert capstan.elongation_pull_to_release(T0, T0, K, C) == pytest.approx(capstan.elongation_pull(T0, K, C))
    assert capstan.elongation_pull_to_release(lo, T0, K, C) == pytest.approx(capstan.elongation_release(lo, K, C))
    assert capstan.elongation_release_to_pull(lo, lo, K, C) == pytest.approx(capstan.elongation_release(lo, K, C))
    assert capstan.elongation_release_to_pull(T0, lo, K, C) == pytest.approx(capstan.elongation_pull(T0, K, C))


def test_minor_loop_breaks_the_paper_rule_but_not_the_profile():
    """docs/concepts/model.md, the tension-profile memory:
    K = 0.5, 0 -> 20 -> 10 -> 25 N gives T_out = 15.16 N exactly."""
    K5 = 0.5
    T_in = ramp(0, 20, 10, 25)
    exact = 25 * math.exp(-K5)  # resumes the pull line at the previous peak already passed
    prof = estimate_batch(T_in, np.zeros_like(T_in), SheathModel(K=K5, compliance=C), n_nodes=400)
    paper, _, _ = capstan.phase_formula_batch(T_in, K5, C, deadband=0.05)
    assert prof.T_out[-1] == pytest.approx(exact, rel=1e-6)
    assert paper[-1] == pytest.approx(20 * math.exp(-K5), rel=1e-3)  # still held: waits for 10 e^2K
    assert abs(paper[-1] - exact) > 0.15 * exact


def test_phase_labels_follow_the_cycle():
    T_in = ramp(0, 20, 5, 20, n=2000)
    t = np.arange(T_in.size) * 1e-3
    ph = estimate_batch(T_in, np.zeros_like(T_in), MODEL, time=t).phase
    # sustained phases (>= 20 ms); the smoothed rate lags a reversal by a few samples
    change = np.flatnonzero(np.diff(ph)) + 1
    starts, ends = np.r_[0, change], np.r_[change, ph.size]
    seq = [Phase(ph[a]) for a, b in zip(starts, ends, strict=False) if b - a >= 20]
    assert seq[0] == Phase.HOLD and T_in[change[0]] == pytest.approx(0.2, abs=0.02)  # readable: past the 0.2 N band
    assert seq[1:] == [Phase.PULL, Phase.PULL_TO_RELEASE, Phase.RELEASE, Phase.RELEASE_TO_PULL, Phase.PULL]
    # the pull->release band ends where T_in = 20 e^-2K
    first_release = starts[np.flatnonzero(ph[starts] == Phase.RELEASE)[0]]
    assert T_in[first_release] == pytest.approx(20 * math.exp(-2 * K), rel=0.01)


@pytest.mark.parametrize("K_", [0.0, 0.3, 1.1])
def test_compiled_batch_equals_online_state_machine(K_):
    """phase_formula_batch is a compiled twin of PhaseFormulaEstimator.step: keep them equal."""
    t = np.arange(6000) * 1e-3
    noise = np.random.default_rng(3).normal(0, 0.05, t.size)
    T_in = 10 + 8 * np.sin(2 * np.pi * 0.8 * t) * np.sin(2 * np.pi * 0.13 * t) + noise
    T_b, e_b, ph_b = capstan.phase_formula_batch(T_in, K_, 2e-4, deadband=0.1, T0=T_in[0])
    est = capstan.PhaseFormulaEstimator(K_, 2e-4, deadband=0.1, T0=T_in[0])
    for k, T in enumerate(T_in):
        T_o, e, ph = est.step(T)
        assert T_o == pytest.approx(T_b[k], rel=1e-12, abs=1e-12)
        assert e == pytest.approx(e_b[k], rel=1e-12, abs=1e-15)
        assert int(ph) == int(ph_b[k])
