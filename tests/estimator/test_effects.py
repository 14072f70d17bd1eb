"""The effect catalogue and its kernel: identifiers, parameters and texts; the base kernel is the profile-memory
estimator, its noise band keeps the memory off the noise's extremes, and every extension at its neutral values is the
base; the compliance is a linear fit; a fitted magnitude the sensors cannot resolve counts as none; the finer routes
hold the coarser ones as special cases.

Tolerances: 1e-9 relative unless stated.
"""
import math

import numpy as np
import pytest

from estimator.offline.effects.catalogue import (
    CATALOGUE,
    EFFECT_IDS,
    NOISE_BAND,
    PRESLIDING_MIN,
    below_resolution,
    effect,
    neutral_values,
    predict,
)
from estimator.offline.effects.kernels import run_extended
from estimator.offline.effects.presliding_kernel import NODE_FORM
from estimator.offline.effects.types import (
    ROUTE_FINE,
    ROUTE_FORMS,
    ROUTE_TWELFTHS,
    Series,
    finer_route,
    route_shape,
    route_values,
)
from estimator.online.distal import estimate_batch
from estimator.sheath import SheathModel
from tests.estimator.effects_series import IDS, K, _history, _pull, grid, series


def test_catalogue_ids_parameters_and_texts():
    assert EFFECT_IDS == IDS
    for eid, e in CATALOGUE.items():
        assert e.id == eid and len(e.cause) > 20 and len(e.signature) > 20 and e.literature.startswith("E")
        assert len(e.extension) > 10 and type(e).__name__ != "Effect"   # one class per effect
        assert e.primary in ("T_out", "x_out") and e.parameters
        for p in e.parameters:
            # the neutral value (off) inside the fitted range, except a pre-sliding travel: 0 is off, and the fit
            # starts at PRESLIDING_MIN (a travel below it is under the floor of x_out)
            inside = p.lower <= p.neutral <= p.upper or (eid == "presliding" and p.neutral == 0.0 < p.lower)
            assert inside and p.unit and p.meaning
            assert all(p.lower <= s <= p.upper for s in p.starts)
        d = e.describe()
        assert d["id"] == eid and all("unit" in q and len(q["bounds"]) == 2 for q in d["parameters"])
    assert effect("stiction") is CATALOGUE["stiction"]
    assert effect("sensor_delay") is CATALOGUE["sensor_lag:T_in"]          # former ids
    for eid in IDS[8:-1]:                                                  # sensor ids name their channel
        e = CATALOGUE[eid]
        assert e.channel == eid.split(":")[1] and e.parameters[0].name.endswith(e.channel)
    with pytest.raises(KeyError, match="known: velocity_friction"):
        effect("backlash")


def test_base_kernel_is_the_profile_memory_estimator():
    T_in = _history()
    T_out, E1 = run_extended(T_in, np.zeros_like(T_in), np.arange(T_in.size) * 1e-3, *grid(100), K=K)
    ref = estimate_batch(T_in, np.zeros_like(T_in), SheathModel(K=K, compliance=1.0), n_nodes=100)
    np.testing.assert_allclose(T_out, ref.T_out, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(E1, ref.elongation, rtol=1e-9, atol=1e-12)


def test_noise_band_keeps_the_memory_from_latching_the_noise_extremes():
    """A pull to 10 N then a 10 s hold read with 50 mN of white noise: the memory rule latches the noise's
    largest excursion (T_out biased by about 3 sigma e^-K), the noise band h takes h e^-K of it off."""
    u, w = grid()
    true = np.concatenate([np.linspace(1.0, 10.0, 400), np.full(2000, 10.0)])
    t = np.arange(true.size) * 5e-3
    sigma, hold = 0.05, slice(600, None)
    noisy = true + sigma * np.random.default_rng(0).standard_normal(true.size)
    ref = run_extended(true, np.zeros_like(true), t, u, w, K=K)[0]
    scale = sigma * math.exp(-K)
    bias = {b: float(np.mean(run_extended(noisy, np.zeros_like(true), t, u, w, K=K, band=b * sigma)[0][hold]
                             - ref[hold])) / scale for b in (0.0, NOISE_BAND)}
    assert bias[0.0] > 2.0, bias
    assert bias[NOISE_BAND] == pytest.approx(bias[0.0] - NOISE_BAND, abs=0.05), bias
    # and on exact data the band is a dead zone: the hold sits h e^-K below the exact memory
    exact = run_extended(true, np.zeros_like(true), t, u, w, K=K, band=NOISE_BAND * sigma)[0]
    np.testing.assert_allclose(exact[hold], ref[hold] - NOISE_BAND * scale, rtol=1e-9)
    with pytest.raises(ValueError, match="band"):
        run_extended(true, np.zeros_like(true), t, u, w, K=K, band=-0.01)


@pytest.mark.parametrize("eid", IDS)
def test_every_extension_at_its_neutral_values_is_the_base(eid):
    s = series(_history(3000, 1), x_in=np.linspace(0, 0.004, 3000))
    base = predict([], {"K": K}, s, compliance=1e-4)
    ext = predict([eid], {"K": K, **neutral_values([effect(eid)])}, s, compliance=1e-4)
    np.testing.assert_allclose(ext.T_out, base.T_out, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ext.x_out, base.x_out, rtol=0, atol=1e-15)


def test_compliance_is_fitted_by_linear_least_squares():
    T_in, x_in = _pull()
    s = series(T_in, x_in)
    truth = predict([], {"K": K}, s, compliance=1.234e-4)
    s2 = Series(s.time, s.x_in, s.T_in, s.velocity, None, truth.x_out, s.u, s.w)
    assert predict([], {"K": K}, s2).compliance == pytest.approx(1.234e-4, rel=1e-9)


def test_presliding_fit_keeps_a_travel_the_sensors_resolve():
    # a base-model recording (no pre-sliding) with x_out: the per-node form, started at 1 um, may not go below
    # PRESLIDING_MIN, where it would differ from the base model only by driving the distal end on the measured x_out
    from estimator.offline.diagnosis.fit import fit_model
    T = np.concatenate((np.linspace(0, 15, 600), np.linspace(15, 2, 500), np.linspace(2, 12, 500)))
    x = np.concatenate((np.linspace(0, 0.005, 600), np.linspace(0.005, 0.001, 500), np.linspace(0.001, 0.004, 500)))
    s0 = series(T, x)
    ref = predict([], {"K": K}, s0, compliance=1e-4)
    s = series(T, x, T_out=ref.T_out, x_out=ref.x_out)
    assert 0.0 < PRESLIDING_MIN <= 0.5 * CATALOGUE["presliding"].knob.ranges[0][1]
    vals, _, _ = fit_model([CATALOGUE["presliding"]], s, [{"K": K, "x_p": 1e-6, NODE_FORM: 1.0}], max_starts=1)
    assert PRESLIDING_MIN <= vals["x_p"] < 1e-3 and vals[NODE_FORM] == 1.0


def test_a_fit_at_the_smallest_resolvable_magnitude_is_below_resolution():
    # pre-sliding at PRESLIDING_MIN (the fit's lower bound, above the neutral 0) does not count as pre-sliding;
    # a travel in its realistic range does, and effects whose range starts at their neutral value never are
    pre = [CATALOGUE["presliding"]]
    assert below_resolution(pre, {"x_p": PRESLIDING_MIN}) and below_resolution(pre, {"x_p": 1.02 * PRESLIDING_MIN})
    assert not below_resolution(pre, {"x_p": 40e-6}) and not below_resolution(pre, {})
    assert not below_resolution([CATALOGUE["velocity_friction"], CATALOGUE["stiction"]], {"c_v": 0.0, "r_s": 0.0})


def test_the_finer_route_holds_the_thirds_as_a_special_case():
    # sixths from thirds (each third's share split over its two sixths) give the same wrap shape
    for r1, r2 in ((1 / 3, 0.5), (0.05, 0.95), (0.7, 0.0), (0.0, 0.0)):
        fine = finer_route({"r_1": r1, "r_2": r2})
        assert set(fine) == {p.name for p in ROUTE_FINE} and all(0.0 <= v <= 1.0 for v in fine.values())
        coarse = route_shape(61, r1, r2)
        sixths = route_shape(61, *(fine[p.name] for p in ROUTE_FINE))
        np.testing.assert_allclose(sixths, coarse, atol=1e-12)
    # the neutral sixths are the uniform route; a share of 1 puts the whole wrap in that sixth
    np.testing.assert_allclose(route_shape(13, *(p.neutral for p in ROUTE_FINE)), np.linspace(0, 1, 13), atol=1e-12)
    u = route_shape(61, 0.0, 0.0, 1.0, 0.5, 0.5)
    assert u[20] == pytest.approx(0.0) and u[30] == pytest.approx(1.0) and u[-1] == pytest.approx(1.0)


def test_the_twelfths_hold_the_sixths_and_the_thirds_as_special_cases():
    # each sixth's share split over its two twelfths (and the thirds through them) gives the same wrap shape
    for sixths in ((0.0, 0.247, 0.2, 0.253, 1.0), (1 / 6, 0.2, 0.25, 1 / 3, 0.5), (0.9, 0.0, 0.5, 0.0, 0.3)):
        fine = finer_route(dict(zip(("r_1", "r_2", "r_3", "r_4", "r_5"), sixths, strict=False)), ROUTE_TWELFTHS)
        assert list(fine) == [p.name for p in ROUTE_TWELFTHS] and all(0.0 <= v <= 1.0 for v in fine.values())
        np.testing.assert_allclose(route_shape(121, *route_values(fine)), route_shape(121, *sixths), atol=1e-12)
    thirds = {"r_1": 0.05, "r_2": 0.95}
    np.testing.assert_allclose(route_shape(121, *route_values(finer_route(thirds, ROUTE_TWELFTHS))),
                               route_shape(121, 0.05, 0.95), atol=1e-12)
    np.testing.assert_allclose(route_shape(25, *(p.neutral for p in ROUTE_TWELFTHS)), np.linspace(0, 1, 25), atol=1e-12)
    # route_values reads the shares in order; r_2 is neutral when only r_1 is given; none without a route
    assert route_values({"K": 1.0, "r_2": 0.4, "r_1": 0.2}) == (0.2, 0.4)
    assert route_values({"r_1": 0.2}) == (0.2, 0.5) and route_values({"K": 1.0}) == ()
    assert set(ROUTE_FORMS) == {"thirds", "fine", "twelfths"} and len(ROUTE_FORMS["twelfths"]) == 11
