"""Per-node pre-sliding kernel (estimator.offline.effects.presliding_kernel): its Coulomb limit is the base
model's memory, a larger pre-sliding tension narrows the friction loop, and bad inputs are refused."""
import numpy as np
import pytest

from estimator.offline.effects.catalogue import predict
from estimator.offline.effects.kernels import run_extended
from estimator.offline.effects.presliding_kernel import NODE_FORM, T_P_MIN, node_presliding, run_node_presliding
from estimator.offline.effects.types import Series
from estimator.sheath import SheathModel


def _drive(n: int = 4000):
    t = np.linspace(0.0, 20.0, n)
    T_in = (6.0 + 5.0 * np.sin(2 * np.pi * 0.25 * t)) * np.minimum(t / 2.0, 1.0)   # from the unloaded rest
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(32)
    return t, T_in, u, w


def test_small_presliding_tension_is_the_coulomb_memory():
    t, T_in, u, w = _drive()
    T_ref, E_ref = run_extended(T_in, np.gradient(T_in, t), t, u, w, K=0.9)
    T_out, E1 = run_node_presliding(T_in, t, u, w, K=0.9, T_p=T_P_MIN)
    assert np.max(np.abs(T_out - T_ref)) < 0.02 * np.ptp(T_ref)
    assert np.max(np.abs(E1 - E_ref)) < 0.02 * np.ptp(E_ref)


def test_larger_presliding_tension_narrows_the_loop_and_rounds_its_corners():
    t, T_in, u, w = _drive()
    late = t > 8.0
    widths = []
    for T_p in (0.01, 0.5, 2.0, 8.0):
        T_out, _ = run_node_presliding(T_in, t, u, w, K=0.9, T_p=T_p)
        # loop width: T_out spread at the same T_in on the pull and release branches (mid tension)
        rising = np.gradient(T_in, t) > 0
        mid = late & (np.abs(T_in - 6.0) < 0.3)
        widths.append(float(np.mean(T_out[mid & ~rising]) - np.mean(T_out[mid & rising])))
    assert all(a > b for a, b in zip(widths, widths[1:], strict=False)), widths
    assert widths[-1] > 0.0          # still a friction loop


def test_fixed_distal_end_holds_back_the_distal_tension():
    t, T_in, u, w = _drive()
    free, _ = run_node_presliding(T_in, t, u, w, K=0.9, T_p=2.0, r=1.0)
    fixed, _ = run_node_presliding(T_in, t, u, w, K=0.9, T_p=2.0, distal=np.zeros_like(t))
    late = t > 8.0
    # with the distal end held, the pieces near it move only by the tendon's strain: less T_out swing
    assert np.ptp(fixed[late]) != pytest.approx(np.ptp(free[late]), rel=0.01)


def test_the_catalogue_runs_the_node_form_with_a_measured_distal_position():
    t, T_in, u, w = _drive(2000)
    c = 8e-5
    T_out, E1 = run_node_presliding(T_in, t, u, w, K=0.9, T_p=T_P_MIN)
    x_in = c * E1 + 1e-4 * np.minimum(t, 1.0)
    x_out = x_in - c * E1
    s = Series(t, x_in, T_in, np.gradient(x_in, t), T_out, x_out, u, w)
    pr = predict(["presliding"], {"K": 0.9, "x_p": 1e-7, NODE_FORM: 1.0}, s)
    assert pr.compliance == pytest.approx(c, rel=0.05)
    assert np.max(np.abs(pr.T_out - T_out)) < 0.05 * np.ptp(T_out)


def test_bad_inputs_are_refused():
    t, T_in, u, w = _drive(100)
    with pytest.raises(ValueError, match="T_p"):
        run_node_presliding(T_in, t, u, w, K=0.9, T_p=0.0)
    with pytest.raises(ValueError, match="r must"):
        run_node_presliding(T_in, t, u, w, K=0.9, T_p=1.0, r=1.5)
    with pytest.raises(ValueError, match="x_p"):
        node_presliding(T_in, T_in, None, t, u, w, x_p=0.0, compliance=1e-4, K=0.9)
    with pytest.raises(ValueError, match="compliance"):
        node_presliding(T_in, T_in, None, t, u, w, x_p=1e-4, compliance=None, K=0.9)


def test_the_coulomb_compliance_of_the_node_form_is_that_of_the_base_memory():
    """The node form's L/EA without a known compliance comes from the base model's memory (the node kernel's
    T_p -> 0 limit): it agrees with the node kernel's own at T_P_MIN to 1e-3."""
    t, T_in, u, w = _drive()
    c = 8e-5
    _, E_node = run_node_presliding(T_in, t, u, w, K=0.9, T_p=T_P_MIN)
    x_in = 1e-4 * np.minimum(t, 1.0) + c * E_node
    x_out = x_in - c * E_node
    node_presliding(T_in, x_in, x_out, t, u, w, x_p=1e-6, compliance=None, K=0.9)
    from estimator.offline.effects.presliding_kernel import _COULOMB
    fitted = _COULOMB[0][1]
    assert fitted == pytest.approx(c, rel=1e-3)
