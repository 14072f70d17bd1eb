"""The data types of the effect catalogue (:mod:`estimator.offline.effects`): a fitted parameter, a
recording prepared for fitting, a model prediction, and the diagnosis's verdict names."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["Parameter", "Series", "Prediction", "NONE", "UNKNOWN", "K_MAX"]

NONE = "none"          # the base model explains the data within the noise
UNKNOWN = "unknown"    # structure left in the residual that no extension explains
K_MAX = 5.0            # upper bound of the friction exponent in fits [-]


@dataclass(frozen=True)
class Parameter:
    """One fitted parameter: name (paper symbol where there is one), SI unit, bounds, neutral value
    (the base model), typical starting values for the fit, and what it means.

    ``rest`` says whether the fit also starts from the parameter read at rest before the first move
    (:func:`estimator.offline.diagnosis_fit.rest_start`: T_in for a tension, x_out - x_in for an encoder
    offset): "" no; "replace": only from that reading (at least 0.1; the pretension); "extend": the starts
    plus that reading when it lies beyond them (the offset of a slack tendon's reading, an encoder offset).
    Either way the best few extensions refitted with the route free also start from it on the uniform
    route (diagnose)."""

    name: str
    unit: str
    lower: float
    upper: float
    neutral: float
    starts: tuple[float, ...]
    meaning: str
    rest: Literal["", "replace", "extend"] = ""


@dataclass(frozen=True, eq=False)
class Series:
    """A recording prepared for fitting: arrays of shape (n,), the model's node grid and noise.

    time [s], x_in [m], T_in [N], velocity dx_in/dt [m/s], T_out [N] or None, x_out [m] or None,
    u (m + 1,) normalised wrap angle of the nodes, w (m + 1,) trapezoid weights (sum 1),
    T_min [N] the tension below which a breakaway is lost in the load-cell noise, sigma_T_in [N]
    the white-noise level of the prepared T_in, slide_travel [m] the distal travel beyond which the measured
    x_out counts as moving (the whole tendon slides; 0: x_out's motion not used by the memory) and slide, int8
    shape (n,) or None, the direction x_out is seen moving in at each sample (effects_kernels.distal_slide).
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

    def slice(self, stop: int) -> "Series":
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
