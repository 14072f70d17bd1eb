"""The data types of the effect catalogue (:mod:`estimator.offline.effects.catalogue`): a fitted parameter, a
recording prepared for fitting, a model prediction, and the diagnosis's verdict names."""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["Parameter", "Series", "Prediction", "NONE", "UNKNOWN", "K_MAX", "route_shape", "ROUTE", "ROUTE_FINE",
           "ROUTE_TWELFTHS", "ROUTE_KEYS", "ROUTE_FORMS", "route_values", "finer_route", "uniform_route"]

NONE = "none"          # the base model explains the data within the noise
UNKNOWN = "unknown"    # structure left in the residual that no extension explains
K_MAX = 5.0            # upper bound of the friction exponent in fits [-]


@dataclass(frozen=True)
class Parameter:
    """One fitted parameter: name (paper symbol where there is one), SI unit, bounds, neutral value
    (the base model), typical starting values for the fit, and what it means.

    ``rest`` says whether the fit also starts from the parameter read at rest before the first move
    (:func:`estimator.offline.diagnosis.fit.rest_start`: T_in for a tension, x_out - x_in for an encoder
    offset): "" no; "replace": only from that reading (at least 0.1; the pretension); "extend": the starts
    plus that reading when it lies beyond them (the offset of a slack tendon's reading, an encoder offset).
    Either way the best few extensions refitted with the route free also start from it on the uniform
    route (diagnose).

    ``discrete`` marks a parameter the least-squares fit does not move (the instant of a step, on which the
    residual depends in steps): it is fitted by a profile over candidate values
    (:func:`estimator.offline.diagnosis.instant.profile_instant`) and then held; it counts in the price."""

    name: str
    unit: str
    lower: float
    upper: float
    neutral: float
    starts: tuple[float, ...]
    meaning: str
    rest: Literal["", "replace", "extend"] = ""
    discrete: bool = False


@dataclass(frozen=True, eq=False)
class Series:
    """A recording prepared for fitting: arrays of shape (n,), the model's node grid and noise.

    time [s], x_in [m], T_in [N], velocity dx_in/dt [m/s], T_out [N] or None, x_out [m] or None,
    u (m + 1,) normalised wrap angle of the nodes, w (m + 1,) trapezoid weights (sum 1),
    T_min [N] the tension below which a breakaway is lost in the load-cell noise, sigma_T_in [N]
    the white-noise level of the prepared T_in, slide_travel [m] the distal travel beyond which the measured
    x_out counts as moving (the whole tendon slides; 0: x_out's motion not used by the memory) and slide, int8
    shape (n,) or None, the direction x_out is seen moving in at each sample (effects_kernels.distal_slide).
    Its arrays are read, never written: a prediction reuses the last few runs of the model's kernel on the same
    arrays (:mod:`estimator.offline.effects.predict`).
    """

    time: np.ndarray
    x_in: np.ndarray
    T_in: np.ndarray
    velocity: np.ndarray
    T_out: np.ndarray | None
    x_out: np.ndarray | None
    u: np.ndarray
    w: np.ndarray
    T_min: float = 0.0
    sigma_T_in: float = 0.0
    slide_travel: float = 0.0
    slide: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def slice(self, stop: int) -> Series:
        """The first ``stop`` samples (the training block)."""
        T_out = None if self.T_out is None else self.T_out[:stop]
        x_out = None if self.x_out is None else self.x_out[:stop]
        slide = None if self.slide is None else self.slide[:stop]      # causal: the slice's own reading
        return Series(self.time[:stop], self.x_in[:stop], self.T_in[:stop], self.velocity[:stop],
                      T_out, x_out, self.u, self.w, self.T_min, self.sigma_T_in, self.slide_travel, slide)


@dataclass(frozen=True)
class Prediction:
    """Model outputs over a series: T_out [N] and x_out [m], shape (n,), and the compliance L/EA
    [m/N] used (fitted by linear least squares on the given mask when x_out was measured)."""

    T_out: np.ndarray
    x_out: np.ndarray
    compliance: float


def route_shape(n1: int, r_1: float, r_2: float, *finer: float) -> np.ndarray:
    """Normalised wrap angle u(s) [-], shape (n1,), at n1 nodes equally spaced in arc length: piecewise
    linear over M = 3 equal thirds (r_1, r_2) or, with ``finer`` = (r_3, ..., r_{M-1}), M equal parts (6 sixths,
    12 twelfths) holding the shares q_k = r_k (1 - q_1 - ... - q_{k-1}) of the total angle, the last share the rest
    (see :data:`estimator.offline.effects.types.ROUTE` and :data:`estimator.offline.effects.types.ROUTE_FINE`).
    A new array each call (the last few shapes are kept: a fit varies the other parameters more often)."""
    return _route_shape(int(n1), tuple(float(v) for v in (r_1, r_2, *finer))).copy()


@functools.lru_cache(maxsize=64)
def _route_shape(n1: int, r: tuple[float, ...]) -> np.ndarray:
    q, left = [], 1.0
    for v in r:
        q.append(left * v)
        left -= q[-1]
    q.append(left)
    knots = np.linspace(0.0, 1.0, len(q) + 1)
    return np.interp(np.linspace(0.0, 1.0, n1), knots, np.concatenate([[0.0], np.cumsum(q)]))


# ---- the route: where along the sheath the curvature sits (the base model's shape parameters) -----
#: shape parameters of the base model: the wrap angle is spread over three equal thirds of the sheath
#: in the shares q1 = r_1, q2 = (1 - r_1) r_2, q3 = (1 - r_1)(1 - r_2); r = (1/3, 1/2) is uniform (E7)
ROUTE = (Parameter("r_1", "-", 0.0, 1.0, 1.0 / 3.0, (1.0 / 3.0,), "share of the wrap angle in the proximal third"),
         Parameter("r_2", "-", 0.0, 1.0, 0.5, (0.5,), "share of the rest in the middle third"))
#: the finer route: six equal sixths, q_k = r_k (1 - q_1 - ... - q_{k-1}), q_6 the rest; the
#: thirds are the special case of pairs of equal sixths (:func:`finer_route`). A single arc over a fifth of
#: the sheath sits inside one third's uniform spread on the coarse route and leaves an elongation residual
#: at reversals of 10-20 um (x_out several times its floor) that the sixths remove
ROUTE_FINE = (Parameter("r_1", "-", 0.0, 1.0, 1.0 / 6.0, (1.0 / 6.0,), "share of the wrap angle in the first sixth"),
              Parameter("r_2", "-", 0.0, 1.0, 0.2, (0.2,), "share of the rest in the second sixth"),
              Parameter("r_3", "-", 0.0, 1.0, 0.25, (0.25,), "share of the rest in the third sixth"),
              Parameter("r_4", "-", 0.0, 1.0, 1.0 / 3.0, (1.0 / 3.0,), "share of the rest in the fourth sixth"),
              Parameter("r_5", "-", 0.0, 1.0, 0.5, (0.5,), "share of the rest in the fifth sixth"))
_ORDINAL = ("first", "second", "third", "fourth", "fifth", "sixth", "seventh", "eighth", "ninth", "tenth", "eleventh")
#: the finest route: twelve equal twelfths, the same share rule; the sixths are pairs of equal
#: twelfths. Two short arcs (11 and 13 % of the sheath, 40 and 60 % of the wrap) sit across sixth boundaries
#: and the sixths fitted on one fold's block misplace them; the twelfths put the wrap where the arcs are
ROUTE_TWELFTHS = tuple(Parameter(f"r_{k}", "-", 0.0, 1.0, 1.0 / (13 - k), (1.0 / (13 - k),),
                                 f"share of the {'wrap angle' if k == 1 else 'rest'} in the {_ORDINAL[k - 1]} twelfth")
                       for k in range(1, 12))
ROUTE_KEYS = tuple(p.name for p in ROUTE_TWELFTHS)
#: the route forms by name (the ``route`` argument of the fits): their shares in order
ROUTE_FORMS = {"thirds": ROUTE, "fine": ROUTE_FINE, "twelfths": ROUTE_TWELFTHS}


def route_values(values: dict) -> tuple[float, ...]:
    """The route shares r_1, r_2, ... held in ``values`` in order (r_2 neutral when only r_1 is given)."""
    r = [float(values[k]) for k in ROUTE_KEYS if k in values]
    return tuple(r + [ROUTE[1].neutral]) if len(r) == 1 else tuple(r)


def finer_route(values: dict, form: tuple = ROUTE_FINE) -> dict[str, float]:
    """The shares of a finer route ``form`` (default the sixths, :data:`ROUTE_FINE`; or :data:`ROUTE_TWELFTHS`)
    of the route held in ``values`` (its shares r_1, r_2, ..., the thirds' neutral when none): its wrap shape
    read at the finer knots, each share taken as its part of the rest."""
    r = route_values(values) or tuple(p.neutral for p in ROUTE)
    u = route_shape(len(form) + 2, *r)
    q, left = np.diff(u), 1.0 - u[:-1]
    return {p.name: float(min(max(q[k] / left[k], 0.0), 1.0)) if left[k] > 1e-12 else 0.5
            for k, p in enumerate(form)}


def uniform_route(form: bool | str) -> dict[str, float]:
    """The shares of a route ``form`` (True: the thirds, :data:`ROUTE`; or a name of :data:`ROUTE_FORMS`) at their
    neutral values: the wrap spread evenly along the sheath."""
    return {p.name: p.neutral for p in (ROUTE_FORMS[form] if isinstance(form, str) else ROUTE)}
