"""The capstan-joint pair model: two distributed Coulomb tendons on one elastic joint, driven by the motor.

The seed pair model (:mod:`estimator.offline.pair.fit`) lets the angle follow each tendon's kinematics at every
sample, with the elongation driven by the measured tension. Here the tendons, the sheath friction
and the joint are one mechanism, the pull-pull pair of the reference simulator (Agrawal et al. 2010;
:mod:`estimator.kernels`), driven by the recorded motor command:

    x_in,a = x_in,a(0) + G (c - c_0),   x_in,b = x_in,b(0) - G (c - c_0)      motor, r = 1 units  (P1)
    T_j(s)                              tension-profile memory of tendon j, K_j, compliance lam   (P2)
    x_out,a = + theta,  x_out,b = - theta,   e_j = x_in,j - x_out,j            both taut on r    (P3)
    T_d,a - T_d,b = k theta + tau_0 (+- tau_c while the joint slides)         joint balance      (P4)

All lengths are in units of the joint pulley radius r, so G = g / r (motor to joint transmission),
lam = (L/EA) / r [rad/N] (tendon compliance seen at the joint), k = k_joint / r [N/rad] (the joint
stiffness k_joint [N m/rad] as a tendon-tension difference per radian), and the
angle is in rad. One step (each sample is split into ``substeps``): the motors move with the joint
held (slip spreads from each proximal end, :func:`estimator.kernels.advance_proximal`), then
the joint settles with the motors held (slip spreads from each distal end and theta solves (P4),
:func:`estimator.kernels.settle_joint`); the compiled sample loop is :mod:`estimator.pair_loops`, which the batch
model (:func:`simulate_pair`) and the per-cycle form (:class:`estimator.online.pair_model.PairModelEstimator`) both
run on a state laid out by :func:`pair_kernel`. So the joint stays put
after a reversal until a slip front reaches a tip - the capstan band of each tendon acting on the joint (E1 with E11,
E13) - and the proximal tensions are an output of the model, not an input.

Both tendons start as uniform profiles at the measured pretensions (E5) with theta = 0; tau_0 is the
distal torque of that rest, so the rest is an equilibrium. Extensions (the effect numbers of docs/concepts/effects.md):

* ``lam_s``  a frictionless series compliance between motor and sheath (drive, load cell, sheath
  compression, E10): a straight run of ``n_series`` nodes with zero wrap angle ahead of the sheath;
* ``tau_c``  Coulomb friction torque in the joint (E11/E12 dead band): the joint moves only when the
  torque imbalance exceeds tau_c;
* ``shape``  initial profile T_i = P e^{-shape g_i} (E5: shape 1 is the pull-slip profile a
  pretension applied from the motor leaves, 0 a uniform profile);
* ``k2``, ``theta_c`` a stiffening joint (E11: the bending section's load grows faster than linear):
  the joint stiffness is k + k2 beyond |theta| > theta_c (the simulator's tissue term,
  :func:`estimator.kernels.load_torque`);
* ``offset`` tension-independent friction (E8): the capstan law acts on T + a, dT/dtheta =
  -mu (T + a), so the profile memory runs on T' = T + a (torques and elongation changes are the
  same in T and T'); the slack floor stays at T' = 0, so a released tendon may carry down to -a,
  an approximation that matters only for a tendon within a of slack;
* ``toe``, ``toe_tension`` a tendon softer at low tension (E9: strands bedding in, a stiffening
  stress-strain law): node compliance lam (1 + rho e^{-T/T_c}), i.e. the elongation is
  sum_i w_i phi(T_i) with phi(T) = T + rho T_c (1 - e^{-T/T_c}). The linear kernels are used with
  per-node weights that change from step to step: each substep is run with the tangent compliance at
  the old profile, then rerun with the secant compliance between the old and that predicted profile
  (second order; with a 40 Hz sample and T_c >= 0.3 N the result moves by < 0.05 deg against 8
  substeps, ``tests/estimator/test_pair_diagnosis.py``). The toe acts on the kernel tension (T + a
  with an E8 offset);
* ``mu_b`` friction of the tendons in the bending section, whose wrap is the joint angle itself (E7
  at the distal end): the joint moves only when T_d,a e^{-+mu_b |theta|} - T_d,b e^{+-mu_b |theta|} - k theta
  - tau_0 leaves zero (signs: moving toward + / -; (P4) is the case mu_b = 0), so the joint stalls at
  large angles while the tensions still rise (docs/results/kaist.md). Not combined with ``toe``,
  ``tau_c`` or ``k2``;
* ``observed``, ``lam_d`` the drive-side observer (E10 on the motor side; docs/results/kaist.md): not a
  property of the mechanism but an estimator that reads the *measured* proximal tensions T_m,j at every
  sample. A frictionless compliance lam_d [rad/N] between each motor and its sheath entry carries the
  measured tension, so the entries sit at
  x_a = x_a0 + G (c - c_0) - lam_d (T_m,a - T_m,a(0)) and x_b = x_b0 - G (c - c_0) - lam_d (T_m,b - T_m,b(0))
  in place of (P1). lam_d = 0 is the command-only model. Not combined with ``toe``, ``tau_c``, ``k2`` or ``mu_b``.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

import estimator.pair_loops as pl
from estimator.distal_slip import distal_gains

__all__ = ["STRUCTURE_PARAMS", "EFFECT_PARAMS", "EFFECT_STRUCTURES", "PairState", "PairKernel", "tendon_arrays",
           "pair_kernel", "simulate_pair"]

#: Parameter names (SI units) of each structure of the pair models, in the order of the offline catalogue
#: (:mod:`estimator.offline.pair.models` adds bounds and start values; tests/estimator/test_pair_model_live.py
#: keeps the two the same). ``seed``: the seed pair model on the measured tensions; ``capstan``: (P1)-(P4).
STRUCTURE_PARAMS: dict[str, tuple[str, ...]] = {
    "seed": ("G", "K_a", "K_b", "lam_a", "lam_b", "theta0"),
    "capstan": ("G", "lam", "K_a", "K_b", "k", "theta0"),
}

#: Parameter names of each pair effect (the effect ids of the offline catalogue; E-numbers of
#: docs/concepts/effects.md): b [rad], tau [s], a [N], shape [-], tau_c [N], lam_s [rad/N], k2 [N/rad],
#: theta_c [rad], toe [-], toe_tension [N], mu_b [1/rad], lam_d [rad/N].
EFFECT_PARAMS: dict[str, tuple[str, ...]] = {
    "capstan_joint": (),
    "joint_backlash": ("b",),
    "sensor_delay": ("tau",),
    "friction_offset": ("a",),
    "pretension_profile": ("shape",),
    "joint_friction": ("tau_c",),
    "series_compliance": ("lam_s",),
    "joint_stiffening": ("k2", "theta_c"),
    "tendon_toe": ("toe", "toe_tension"),
    "bending_friction": ("mu_b",),
    "drive_observer": ("lam_d",),
}

#: The structures each effect's model runs on (``capstan_joint`` is the step from the seed structure to the
#: capstan structure itself). The offline catalogue offers a subset (``bending_friction`` and
#: ``drive_observer`` only in the shared models or on request).
EFFECT_STRUCTURES: dict[str, tuple[str, ...]] = {
    "capstan_joint": ("seed",),
    "joint_backlash": ("seed", "capstan"),
    "sensor_delay": ("seed", "capstan"),
    "friction_offset": ("seed", "capstan"),
    "pretension_profile": ("capstan",),
    "joint_friction": ("capstan",),
    "series_compliance": ("capstan",),
    "joint_stiffening": ("capstan",),
    "tendon_toe": ("capstan",),
    "bending_friction": ("capstan",),
    "drive_observer": ("capstan",),
}


def tendon_arrays(K: float, lam: float, n_nodes: int = 24, lam_s: float = 0.0, n_series: int = 3):
    """Node arrays of one tendon (constant curvature), proximal to distal.

    Parameters
    ----------
    K : friction exponent mu * wrap angle [-], >= 0
    lam : compliance of the sheathed tendon [rad/N] (units of r), > 0
    n_nodes : elements along the sheath
    lam_s : frictionless series compliance ahead of the sheath [rad/N], >= 0 (none when 0)
    n_series : elements of the series run (used when ``lam_s`` > 0)

    Returns
    -------
    lo, hi, dlo, dhi, w : ndarray, shape (m,), m = n_nodes + 1 (+ n_series): e^{-g}, e^{+g},
        distal gains (:func:`estimator.distal_slip.distal_gains`) and trapezoid weights [rad/N]
    c_pull, c_rel : float, elongation per distal tension of the whole tendon sliding [rad/N]
    """
    g = K * np.linspace(0.0, 1.0, n_nodes + 1)
    w = np.full(n_nodes + 1, lam / n_nodes)
    w[0] *= 0.5
    w[-1] *= 0.5
    if lam_s > 0.0:
        ws = np.full(n_series, lam_s / n_series)
        ws[0] *= 0.5
        w[0] += 0.5 * lam_s / n_series
        g = np.concatenate([np.zeros(n_series), g])
        w = np.concatenate([ws, w])
    lo, hi = np.exp(-g), np.exp(g)
    dlo, dhi = distal_gains(g)
    return lo, hi, dlo, dhi, w, float(w @ lo) / lo[-1], float(w @ hi) / hi[-1]


@functools.lru_cache(maxsize=256)
def _node_arrays(K: float, lam: float, n_nodes: int, lam_s: float) -> tuple:
    """:func:`tendon_arrays`, memoised on its exact arguments: a least-squares Jacobian perturbs one
    parameter at a time, so most evaluations reuse both tendons' arrays (building them cost ~20 % of a
    KAIST-length run). The kernels only read them; ``tests/estimator/test_pair_diagnosis.py`` checks
    that a run leaves them unchanged."""
    return tendon_arrays(K, lam, n_nodes, lam_s)



@dataclass
class PairState:
    """The state of one run of the model (:mod:`estimator.pair_loops`, module docstring): the profiles ``prof``
    (2, m) [N], the scalars ``st`` (N_ST,) and the rigid stop ``band`` (3, 1)."""

    prof: np.ndarray
    st: np.ndarray
    band: np.ndarray


@dataclass(frozen=True)
class PairKernel:
    """One parameter set of the model, checked and laid out for :func:`estimator.pair_loops.run_pair`.

    Attributes
    ----------
    kind : the variant, one of the ``KIND_*`` of :mod:`estimator.pair_loops`
    nodes : ndarray, shape (2, 5, m), node arrays of tendons a and b (lo, hi, dlo, dhi, w), read only
    par : ndarray, shape (N_PAR,), the parameters at the ``P_*`` indices
    P : ndarray, shape (2, m), initial profiles [N] (kernel tension: T + a with the E8 offset a)
    substeps : steps per sample, >= 1
    offset : the E8 offset a [N], subtracted from the kernel's proximal tensions
    """

    kind: int
    nodes: np.ndarray
    par: np.ndarray
    P: np.ndarray
    substeps: int
    offset: float

    def start(self, c0: float, ma0: float = 0.0, mb0: float = 0.0) -> PairState:
        """A fresh state at rest for a run whose first command is ``c0`` [rad] (theta = 0, uniform or shaped
        profiles, (P4) at rest); ``ma0``, ``mb0`` [N]: the first measured proximal tensions (observer only)."""
        m = self.nodes.shape[2]
        s = PairState(np.empty((2, m)), np.empty(pl.N_ST), np.empty((3, 1)))
        pl.start_pair(float(c0), float(ma0), float(mb0), self.P, self.nodes, self.par, s.prof, s.st, s.band)
        return s

    def run(self, state: PairState, c: np.ndarray, Tm: np.ndarray, i0: int, i1: int, theta: np.ndarray,
            T_in: np.ndarray) -> None:
        """Advance ``state`` over the samples [i0, i1) of ``c`` [rad], shape (n,) (``Tm`` [N], shape (n, 2) or
        (0, 2) without the observer), writing ``theta`` [rad] (n,) and the kernel's proximal tensions ``T_in``
        [N] (n, 2) (the E8 offset not yet subtracted)."""
        pl.run_pair(self.kind, c, Tm, i0, i1, self.substeps, self.nodes, self.par, state.prof, state.st, state.band,
                 theta, T_in)


def pair_kernel(pretension: tuple[float, float], G: float, lam: tuple[float, float], K: tuple[float, float],
                k: float, *, lam_s: float = 0.0, tau_c: float = 0.0, shape: float = 0.0, offset: float = 0.0,
                k2: float = 0.0, theta_c: float = 0.0, toe: float = 0.0, toe_tension: float = 1.0, mu_b: float = 0.0,
                n_nodes: int = 24, substeps: int = 1, observed: bool = False, lam_d: float = 0.0) -> PairKernel:
    """The model (module docstring, (P1)-(P4)) for one parameter set, checked and laid out for the compiled loop.

    The parameters are those of :func:`simulate_pair` (same units and ranges); ``observed`` True selects the
    drive-side observer, which then reads the measured proximal tensions at every sample.

    Raises
    ------
    ValueError
        A non-finite or out-of-range parameter, ``mu_b`` with ``toe``, ``tau_c`` or ``k2``, or the observer
        with ``toe``, ``tau_c``, ``k2`` or ``mu_b``.
    """
    _check_params(pretension, G, lam, K, k, lam_s=lam_s, tau_c=tau_c, shape=shape, offset=offset, k2=k2,
                  theta_c=theta_c, toe=toe, toe_tension=toe_tension, mu_b=mu_b, lam_d=lam_d)
    if observed and (toe > 0.0 or tau_c > 0.0 or k2 > 0.0 or mu_b > 0.0):
        raise ValueError("the drive-side observer (observed=) is not combined with toe, tau_c, k2 or mu_b")
    arrs = [_node_arrays(float(Kj), float(lj), int(n_nodes), float(lam_s)) for Kj, lj in zip(K, lam, strict=True)]
    P = np.array([(P0 + offset) * np.exp(-shape * np.log(a[1])) for P0, a in zip(pretension, arrs, strict=True)])
    nodes = np.array([a[:5] for a in arrs])
    par = np.zeros(pl.N_PAR)
    par[pl.P_G], par[pl.P_K], par[pl.P_TAU_C], par[pl.P_K2] = float(G), float(k), float(tau_c), float(k2)
    par[pl.P_THC] = float(theta_c) if k2 > 0.0 else pl.BIG
    par[pl.P_RHO], par[pl.P_TC] = float(toe), float(toe_tension)
    par[pl.P_MUB], par[pl.P_LAM_D] = float(mu_b), float(lam_d)
    par[pl.P_CPA], par[pl.P_CRA], par[pl.P_CPB], par[pl.P_CRB] = arrs[0][5], arrs[0][6], arrs[1][5], arrs[1][6]
    if observed:
        kind = pl.KIND_OBSERVED
    elif toe > 0.0:
        kind = pl.KIND_TOE
    elif mu_b > 0.0:
        kind = pl.KIND_BEND
    else:
        kind = pl.KIND_PLAIN
    return PairKernel(kind, nodes, par, P, max(int(substeps), 1), float(offset))


def simulate_pair(command, pretension: tuple[float, float], G: float, lam: tuple[float, float],
                  K: tuple[float, float], k: float, *, lam_s: float = 0.0, tau_c: float = 0.0, shape: float = 0.0,
                  offset: float = 0.0, k2: float = 0.0, theta_c: float = 0.0, toe: float = 0.0,
                  toe_tension: float = 1.0, mu_b: float = 0.0, n_nodes: int = 24,
                  substeps: int = 1, observed: tuple[np.ndarray, np.ndarray] | None = None,
                  lam_d: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Run the capstan-joint pair model (module docstring, (P1)-(P4)) over a recorded command.

    Parameters
    ----------
    command : ndarray, shape (n,)
        Motor-side command c [rad].
    pretension : (P_a, P_b) [N], uniform initial tensions (measured at rest), >= 0
    G : motor-to-joint transmission g / r [-], >= 0
    lam : (lam_a, lam_b), tendon compliances (L/EA) / r [rad/N], > 0
    K : (K_a, K_b), friction exponents [-], >= 0
    k : joint stiffness / r [N/rad], > 0
    lam_s : series compliance [rad/N] (E10); tau_c : joint friction [N] (torque / r); shape : initial
        profile exponent in [0, 1] (E5); offset : tension offset a of the capstan law [N] (E8);
        k2 : extra joint stiffness [N/rad] beyond |theta| > theta_c [rad] (E11 stiffening, none when 0)
    toe : extra compliance of the tendon at zero tension, as a ratio rho >= 0 (E9; none when 0: the
        kernel is then the linear one, bit for bit); toe_tension : its tension scale T_c [N] > 0. The
        tendon compliance is lam (1 + rho e^{-T/T_c}) (module docstring, ``toe``)
    mu_b : friction coefficient of the tendons in the bending section [1/rad], >= 0; its wrap is the
        joint angle (module docstring, ``mu_b``; none when 0: the kernel is then the plain one, bit for
        bit); not with ``toe``, ``tau_c`` or ``k2``
    observed : (T_a, T_b), the *measured* proximal tensions [N], each of shape (n,), or None (default: the
        command-only model). Given, the model runs as the drive-side observer (module docstring,
        ``lam_d``): each sheath entry sits at the motor position minus ``lam_d`` times the measured
        tension's change since the first sample. Not combined with ``toe``, ``tau_c``, ``k2`` or ``mu_b``
    lam_d : drive-side compliance [rad/N] >= 0 of the observer (with ``observed``; 0 gives the
        command-only model's angle to rounding)
    n_nodes : elements per sheath
    substeps : steps per sample; the model is rate-independent and the splitting error of one step
        per 40 Hz sample was below 1e-12 rad on the KAIST commands, so 1 is the default

    Returns
    -------
    theta : ndarray, shape (n,), joint angle from the start [rad]
    T_in : ndarray, shape (n, 2), proximal tensions of tendons a and b [N]

    Raises
    ------
    ValueError
        A non-finite or out-of-range parameter, a command that is not 1-D and finite, or ``mu_b`` with
        ``toe``, ``tau_c`` or ``k2``; ``observed`` not two finite arrays of the command's shape, or with
        ``toe``, ``tau_c``, ``k2`` or ``mu_b``.
    """
    c = np.ascontiguousarray(command, dtype=np.float64)
    if c.ndim != 1 or c.size == 0 or not np.all(np.isfinite(c)):
        raise ValueError("command must be a non-empty 1-D array of finite angles [rad]")
    kern = pair_kernel(pretension, G, lam, K, k, lam_s=lam_s, tau_c=tau_c, shape=shape, offset=offset, k2=k2,
                       theta_c=theta_c, toe=toe, toe_tension=toe_tension, mu_b=mu_b, n_nodes=n_nodes,
                       substeps=substeps, observed=observed is not None, lam_d=lam_d)
    Tm = np.zeros((0, 2))
    if observed is not None:
        parts = [np.asarray(x, dtype=np.float64) for x in observed]
        if len(parts) != 2 or any(x.shape != c.shape or not np.all(np.isfinite(x)) for x in parts):
            raise ValueError(f"observed must be two finite arrays of the command's shape {c.shape} (the measured "
                             "proximal tensions T_a, T_b [N])")
        Tm = np.stack(parts, axis=1)
    theta = np.empty(c.size)
    T_in = np.empty((c.size, 2))
    state = kern.start(c[0], *(Tm[0] if observed is not None else (0.0, 0.0)))
    kern.run(state, c, Tm, 0, c.size, theta, T_in)
    return theta, T_in - offset


def _check_params(pretension: tuple[float, float], G: float, lam: tuple[float, float], K: tuple[float, float],
                  k: float, *, lam_s: float, tau_c: float, shape: float, offset: float, k2: float, theta_c: float,
                  toe: float, toe_tension: float, mu_b: float, lam_d: float) -> None:
    """The parameters of :func:`pair_kernel` checked (its Raises)."""
    vals = {"G": G, "lam_a": lam[0], "lam_b": lam[1], "K_a": K[0], "K_b": K[1], "k": k, "lam_s": lam_s,
            "tau_c": tau_c, "shape": shape, "offset": offset, "k2": k2, "theta_c": theta_c, "P_a": pretension[0],
            "P_b": pretension[1], "mu_b": mu_b, "lam_d": lam_d}
    for name, v in vals.items():
        if not math.isfinite(v) or v < 0.0:
            raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
    if min(lam) <= 0.0 or k <= 0.0:
        raise ValueError(f"lam_a, lam_b and k must be > 0, got {lam!r}, {k!r}")
    if not 0.0 <= shape <= 1.0:
        raise ValueError(f"shape must be in [0, 1], got {shape!r}")
    if not (math.isfinite(toe) and toe >= 0.0 and math.isfinite(toe_tension) and toe_tension > 0.0):
        raise ValueError(f"toe must be finite and >= 0 and toe_tension finite and > 0, got {toe!r}, {toe_tension!r}")
    if mu_b > 0.0 and (toe > 0.0 or tau_c > 0.0 or k2 > 0.0):
        raise ValueError(f"mu_b (bending-section friction) is not combined with toe, tau_c or k2, got mu_b={mu_b!r}, "
                         f"toe={toe!r}, tau_c={tau_c!r}, k2={k2!r}")
