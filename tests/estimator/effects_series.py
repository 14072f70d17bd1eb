"""The series the effect tests drive the kernel with: the effect ids in catalogue order, the tendon's K, length
and EA, the nodes of a uniform route, a Series from a proximal tension and position, a random tension history and a
monotone pull."""
import numpy as np

from estimator.offline.effects.types import Series
from estimator.sheath import SheathModel

IDS = ("velocity_friction", "pretension", "curvature_drift", "tendon_stiffening", "stiction", "friction_offset",
       "presliding", "distal_backlash",
       "sensor_offset:T_in", "sensor_offset:T_out", "sensor_gain:T_in", "sensor_gain:T_out", "sensor_lag:T_in",
       "sensor_lag:T_out", "sensor_drift:T_in", "sensor_drift:T_out", "sensor_offset:x_in", "sensor_offset:x_out",
       "sensor_lag:x_in", "sensor_lag:x_out", "friction_step")
K, L, EA = 0.7, 1.5, 15000.0
NODES = 32


def grid(m=NODES):
    shape, weight = SheathModel(K=1.0, compliance=1.0).nodes(m)
    return shape, weight


def series(T_in, x_in=None, dt=1e-3, velocity=None, T_out=None, x_out=None):
    T_in = np.asarray(T_in, dtype=float)
    t = np.arange(1, T_in.size + 1) * dt
    x_in = np.zeros_like(T_in) if x_in is None else np.asarray(x_in, dtype=float)
    v = np.gradient(x_in, t) if velocity is None else np.asarray(velocity, dtype=float)
    u, w = grid()
    return Series(t, x_in, T_in, v, T_out, x_out, u, w)


def _history(n=6000, seed=0):
    rng = np.random.default_rng(seed)
    knots = np.concatenate(([0.0], rng.uniform(0.5, 20.0, 30)))
    return np.interp(np.linspace(0, knots.size - 1, n), np.arange(knots.size), knots)


def _pull(T_max=15.0, n=2000):
    """A monotone pull from 0 with the proximal end moving at a constant 5 mm/s."""
    T_in = np.linspace(0.0, T_max, n)
    x_in = np.linspace(0.0, 0.005 * n * 1e-3, n)
    return T_in, x_in
