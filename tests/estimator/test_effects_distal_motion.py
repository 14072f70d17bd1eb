"""The distal end's motion in the kernel. A distal end seen moving the way the proximal one does (beyond the
encoder's resolution) says the slip has reached it and the whole tendon slides, which pins K on a release where the
memory alone would hold; a T_in that turns back ends the slide. A slack tendon holds the distal end while the
proximal end moves on; the slack ends when the paid-out length is taken up, a tension is held or one no noise can
give is read, not on one noise sample; a tendon released against a weak load, or one whose distal end is carried
along, stays taut under the slack threshold.

Tolerances: closed forms 1e-9 relative unless stated.
"""
import math

import numpy as np
import pytest

from estimator.offline.effects import catalogue as effects_module
from estimator.offline.effects.catalogue import (
    predict,
)
from estimator.offline.effects.kernels import distal_slide, run_extended
from estimator.offline.effects.predict import SLACK_HELD, SLACK_SIGMAS, SLACK_TAUT, SLACK_WINDOW, slack_hold
from estimator.offline.effects.types import (
    Series,
)
from tests.estimator.effects_series import K, grid, series


def test_distal_slide_reads_motion_beyond_the_resolution_only():
    rng = np.random.default_rng(3)
    x = np.concatenate([np.zeros(200), np.linspace(0.0, 1e-3, 300), np.full(200, 1e-3), np.linspace(1e-3, 0.0, 300)])
    d = distal_slide(x + 2e-7 * rng.standard_normal(x.size), 2e-6, 5)
    assert not d[:200].any() and not d[505:700].any()          # rest and hold: noise (0.2 um) under 2 um
    assert (d[220:500] == 1).mean() > 0.9 and (d[720:1000] == -1).mean() > 0.9
    assert not (d[:500] == -1).any() and not (d[700:] == 1).any()
    with pytest.raises(ValueError, match="travel"):
        distal_slide(x, 0.0)
    with pytest.raises(ValueError, match="window"):
        distal_slide(x, 1e-6, 0)


def test_a_distal_end_seen_moving_makes_the_whole_tendon_slide():
    """A constant-force load F: the true release sits at T_in = F e^-K, on the
    edge of the band. With a K that is too large (here 0.9 for a true 0.7) the memory alone holds the pulled
    T_out there (T_in stays inside its band) and matches the constant F whatever K is; the measured distal end
    moving with the proximal one says the tendon slides, and the model's T_out is then T_in e^{K} - wrong for a
    wrong K, which is what lets the fit find K from the release too."""
    u, w = grid()
    F, K_true, K_fit = 5.0, 0.7, 0.9
    T_in = np.concatenate([np.linspace(0.5, F * math.exp(K_true), 300), np.full(500, F * math.exp(K_true)),
                           np.linspace(F * math.exp(K_true), F * math.exp(-K_true), 100),
                           np.full(500, F * math.exp(-K_true))])
    x_in = np.concatenate([np.linspace(0.0, 1e-3, 300), np.linspace(1e-3, 6e-3, 500), np.full(100, 6e-3),
                           np.linspace(6e-3, 1e-3, 500)])
    t = np.arange(T_in.size) * 5e-3
    v = np.gradient(x_in, t)
    slide = np.sign(v).astype(np.int8)           # the distal end moves with the proximal one
    slide[800:900] = 0                           # and holds while the proximal tension falls through the band
    held = run_extended(T_in, v, t, u, w, K=K_fit)[0]
    seen = run_extended(T_in, v, t, u, w, K=K_fit, slide=slide)[0]
    release = slice(950, None)
    np.testing.assert_allclose(held[release], F * math.exp(K_true - K_fit), rtol=1e-9)    # the pulled T_out held
    np.testing.assert_allclose(seen[release], F * math.exp(K_fit - K_true), rtol=1e-9)    # full slip at T_in e^K
    # with the right K both agree with the load: the reading of x_out changes nothing there
    np.testing.assert_allclose(run_extended(T_in, v, t, u, w, K=K_true, slide=slide)[0][release], F, rtol=1e-9)
    # a T_in that turns back while the distal end is still seen moving (the averaged T_in turns before the distal
    # end stops at a reversal) ends the slide and starts none: T_out held at the pulled value, as without x_out
    # (a slide restarted there as a breakaway would put T_out low through the reversal)
    turn = np.concatenate([np.linspace(0.5, 10.0, 300), np.linspace(10.0, 8.0, 20)])
    xt = np.linspace(0.0, 2e-3, turn.size)                                   # the proximal end still pulling
    tt = np.arange(turn.size) * 5e-3
    vt = np.gradient(xt, tt)
    up = np.ones(turn.size, dtype=np.int8)
    for r_s in (0.0, 0.3):
        alone = run_extended(turn, vt, tt, u, w, K=K_fit, r_s=r_s, sigma=0.01)[0]
        seen_t = run_extended(turn, vt, tt, u, w, K=K_fit, r_s=r_s, sigma=0.01, slide=up)[0]
        np.testing.assert_array_equal(seen_t[300:], alone[300:])
        assert np.ptp(seen_t[301:]) == 0.0                                   # held through the turn
    # no motion seen, or motion against the proximal end's: the memory alone
    np.testing.assert_array_equal(run_extended(T_in, v, t, u, w, K=K_fit, slide=np.zeros_like(slide))[0], held)
    np.testing.assert_array_equal(run_extended(T_in, v, t, u, w, K=K_fit, slide=-slide)[0], held)


def test_a_slack_tendon_holds_the_distal_end_while_the_proximal_end_moves_on(monkeypatch):
    # exact tensions: no noise band (NOISE_BAND, a dead zone of 3 sigma on a reading), only the slack rule's sigma
    monkeypatch.setattr(effects_module, "NOISE_BAND", 0.0)
    # pull, release to zero tension while the proximal end goes on back (the tendon goes slack), pull again
    T = np.concatenate((np.linspace(0, 10, 1000), np.linspace(10, 0, 1000), np.zeros(500), np.linspace(0, 10, 1000)))
    x = np.concatenate((np.linspace(0, 3e-3, 1000), np.linspace(3e-3, 1e-3, 1000), np.linspace(1e-3, -1e-3, 500),
                        np.linspace(-1e-3, 2e-3, 1000)))
    sigma = 0.01
    s = series(T, x)
    s = Series(s.time, s.x_in, s.T_in, s.velocity, None, None, s.u, s.w, 0.0, sigma)
    pr = predict([], {"K": K}, s, compliance=1e-4)
    taut = T >= SLACK_SIGMAS * sigma
    last = int(np.flatnonzero(taut[:2500])[-1])
    np.testing.assert_allclose(pr.x_out[last:2500], pr.x_out[last])       # held where the tendon went slack
    assert abs(pr.x_out[last] - x[last]) < 1e-5 < np.ptp(x[last:2500])      # while the proximal end moved 2 mm
    # taut again (the tension held for SLACK_WINDOW samples: this pull rises before the proximal end is back
    # where it went slack): x_out = x_in - (L/EA) E1 as without slack; noiseless data (sigma 0) are never held
    free = predict([], {"K": K}, series(T, x), compliance=1e-4)
    again = 2500 + int(np.flatnonzero(taut[2500:])[0])
    np.testing.assert_allclose(pr.x_out[again - 1:again + 1], pr.x_out[last])
    settled = taut.copy()
    settled[again:again + SLACK_WINDOW - 1] = False
    np.testing.assert_allclose(pr.x_out[settled], free.x_out[settled], atol=1e-15)
    assert np.ptp(free.x_out[last:2500]) > 1e-3
    np.testing.assert_array_equal(slack_hold(T, 0.0), np.arange(T.size))
    np.testing.assert_array_equal(slack_hold(T, 0.0, x), np.arange(T.size))


def test_a_noise_sample_does_not_end_a_slack_phase_a_held_tension_does():
    # in a slack phase (T_in at zero) one sample of noise above the threshold does not put the distal end back on
    # x_in: the slack ends when the proximal end is back where it went slack, when the tension is held above the
    # threshold, or at SLACK_TAUT x the threshold
    thr = 0.03
    n = 400
    T = np.concatenate((np.full(100, 1.0), np.zeros(n)))
    x = np.concatenate((np.full(100, 2e-3), np.linspace(2e-3, 0.0, n)))      # the proximal end pays out
    blip = T.copy()
    blip[300] = 1.2 * thr
    idx = slack_hold(blip, thr, x)
    assert np.all(idx[100:] == 99)                                           # held through the blip
    assert slack_hold(blip, thr)[300] == 300                                 # (by T_in alone it was not)
    strong = T.copy()
    strong[300] = 1.01 * SLACK_TAUT * thr
    assert slack_hold(strong, thr, x)[300] == 300                            # a tension the noise cannot give
    held = T.copy()
    held[300:] = 1.5 * thr                                                   # a taut tendon at low tension
    idx = slack_hold(held, thr, x)
    assert idx[300] == 99 and idx[300 + SLACK_WINDOW - 1] == 300 + SLACK_WINDOW - 1
    back = np.concatenate((T, np.full(50, 0.5 * thr), np.full(10, 1.2 * thr)))
    xb = np.concatenate((x, np.linspace(0.0, 2.5e-3, 50), np.full(10, 2.5e-3)))   # proximal end back past 2 mm
    assert slack_hold(back, thr, xb)[550] == 550


def test_a_tendon_released_against_a_weak_load_stays_taut_under_the_threshold():
    # a 125 N/m joint released at K 1.4 pulls the tendon back at T_in = T_out e^-K, 1-3 sigma of the reading; by
    # the sample alone every sample under the 3 sigma threshold would be slack. Held above zero on both sides, it
    # is taut; a drop to zero is slack at once
    rng = np.random.default_rng(3)
    thr = 0.03                                                               # SLACK_SIGMAS sigma
    sigma = thr / SLACK_SIGMAS
    low = 0.8 * thr + sigma * rng.standard_normal(300)                       # taut, mostly below thr
    assert np.mean(low < thr) > 0.6
    T = np.concatenate((np.full(100, 1.0), low, sigma * rng.standard_normal(300)))
    x = np.concatenate((np.full(100, 3e-3), np.linspace(3e-3, 1e-3, 300), np.linspace(1e-3, 0.0, 300)))
    idx = slack_hold(T, thr, x)
    k = np.arange(100, 400 - SLACK_HELD)
    np.testing.assert_array_equal(idx[k], k)                                 # taut through the release
    assert 400 - SLACK_HELD <= idx[400] < 400 and np.all(idx[400:] == idx[400])   # slack from the drop on
    old = np.flatnonzero(low < thr)[0] + 100                                 # by the sample alone: slack at the
    assert slack_hold(T, thr)[old] < old                                     # first dip


def test_a_tendon_whose_distal_end_is_carried_along_is_taut_at_any_tension():
    # a 97 N/m joint released to 0.85 mm keeps the tendon taut at T_out 0.08 N, so T_in = T_out e^-1.43 = 0.012 N,
    # 0.4 sigma of its load cell: no rule on T_in tells that from a slack tendon. The distal end moving the way the
    # proximal end does says the tendon carries the motion: taut
    thr = 0.03
    n = 300
    T = np.concatenate((np.full(100, 1.0), np.full(n, 0.13 * thr)))          # 0.4 sigma
    x = np.concatenate((np.full(100, 2e-3), np.linspace(2e-3, 1e-3, n)))
    assert np.all(slack_hold(T, thr, x)[100:] == 99)                          # held slack by T_in alone
    moving = np.zeros(T.size, dtype=bool)
    moving[100:] = True
    k = np.arange(100, 100 + n)
    np.testing.assert_array_equal(slack_hold(T, thr, x, moving)[k], k)       # taut while carried along
    moving[250:] = False                                                     # the distal end stops: slack again
    idx = slack_hold(T, thr, x, moving)
    assert idx[249] == 249 and np.all(idx[250:] == 249)
