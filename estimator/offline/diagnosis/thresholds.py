"""Every tuned number of the single-tendon diagnosis, with its unit and meaning, and how the per-effect bars at the
floor are computed from clean recordings (:func:`floor_scores`).

The procedure that uses them is :func:`estimator.offline.diagnosis.selection.diagnose`; where each number comes from
and on which recordings it was checked is in the thresholds table of docs/concepts/diagnosis.md. The rules read them as
attributes of this module at call time (``thresholds.STRUCTURE_RATIO``), so a test may set one with ``monkeypatch``.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

__all__ = ["floor_scores", "PENALTY", "STRUCTURE_RATIO", "VALIDATION_FRACTION", "SECOND_ROUND", "MODEL_RESOLUTION",
           "SCREEN_SHARE", "TRIM", "POLISH", "RANK_FACTOR", "STRONG_SCORE", "WEAK_STRUCTURE", "MID_SCORE", "EXCESS_MIN",
           "FLOOR_FACTOR",
           "FLOOR_SCORE", "FLOOR_SCORE_WITHOUT", "EXCESS_MIN_WITHOUT", "STICK_SLIP_RATIO", "STICK_SLIP_WEAK",
           "STICK_SLIP_WEAK_SCORE", "ROUTE_SCORE", "DOMINANT_SCORE", "OFFSET_FLOORS", "STICK_SLIP_WINDOW",
           "STICK_SLIP_SPEED", "STICK_SLIP_HOLD", "STICK_SLIP_MIN_SAMPLES", "STICK_SLIP_MIN_MOVE",
           "STICK_SLIP_MIN_HOLD", "RELEASE_SHARE", "HELD_STEPS", "HELD_SHARE", "NEAR_HELD_SHARE", "AT_END_SPEED",
           "AT_END_BAND", "AT_END_SHARE", "AT_END_HIDES", "SLIDE_SEEN", "SLIDE_QUANTA", "SLIDE_SIGMAS",
           "SLIDE_SHARE", "FIT_TOL", "CHOICE_TOL", "K_RESTART", "PLATEAU_BISECTIONS", "REST_MIN_S", "REST_RESOLUTIONS",
           "REST_TENSION_SIGMAS", "REST_TENSION_RATIO", "HAND_WINDOW", "HAND_SLIP_SPEED", "HAND_MIN_SLIP_S",
           "HAND_LAG_MIN", "HAND_SPEED_MIN", "HAND_T_MIN", "HAND_WEAK_SCORE"]

# ---- model choice: the split, the scores, the price ------------------------------------------------------------
VALIDATION_FRACTION = 0.35  # [-] share of the training block each fold validates on
TRIM = 0.02                 # [-] share of the largest residuals (of both models, paired) left out of a score
MODEL_RESOLUTION = 0.003    # [-] the base model's own resolution, share of the signal's range, in the noise floor
PENALTY = 0.30              # [-] price per extra parameter on the validation score S (base = 1)
RANK_FACTOR = 2.0           # [-] among acceptable extensions, each extra parameter must divide S by this
SECOND_ROUND = 6            # [count] best single extensions tried together with the first accepted one
#: [-] a second cause beside the first at its floor is fitted only when its linearised share of the fit block's cost
#: (:mod:`estimator.offline.diagnosis.screen`) reaches this much of its price (PENALTY per parameter): a safety factor
#: of 3 on the linear model (the partners named on the development recordings remove 1.3-2.9 times their price in it).
#: The same bound screens the single candidates at the base (:mod:`estimator.offline.diagnosis.singles`)
SCREEN_SHARE = 1.0 / 3.0
POLISH = 3                  # [count] best single extensions refitted with the route shares free
STRUCTURE_RATIO = 3.0       # [-] validation rmse / noise floor above this on a signal: structure is left
DOMINANT_SCORE = 0.1        # [-] an extension with S below this removes nearly all of a structure: it is the cause
ROUTE_SCORE = 0.5           # [-] a finer route replaces the coarser one as the base when its S is below this

# ---- at the floor: what is enough to name an effect ------------------------------------------------------------
STRONG_SCORE = 0.15         # [-] at the floor, an extension with S below this is named
WEAK_STRUCTURE = 2.0        # [-] a base structure ratio above this (still at the floor) lowers the bar to MID_SCORE
MID_SCORE = 0.5             # [-] the bar on S for a base between WEAK_STRUCTURE and STRUCTURE_RATIO
EXCESS_MIN = 3.0            # [floor^2] ... or an extension removing this much of the base's B = sum ratio^2: B (1 - S)
FLOOR_FACTOR = 0.6          # [-] an effect's own bar: this times the lowest S it reached on a clean recording
#: [-] per effect id, the bar FLOOR_FACTOR x its lowest S on clean recordings at the floor (at most MID_SCORE)
FLOOR_SCORE: dict[str, float] = {
    "curvature_drift": 0.45, "distal_backlash": 0.12, "friction_offset": 0.39, "presliding": 0.47, "pretension": 0.50,
    "sensor_drift:T_in": 0.36, "sensor_drift:T_out": 0.45, "sensor_gain:T_in": 0.42, "sensor_lag:T_in": 0.41,
    "sensor_lag:T_out": 0.50, "sensor_lag:x_in": 0.45, "sensor_lag:x_out": 0.46, "sensor_offset:T_in": 0.41,
    "sensor_offset:T_out": 0.42, "sensor_offset:x_in": 0.37, "stiction": 0.42, "tendon_stiffening": 0.24,
    "velocity_friction": 0.50}
#: [-] keyed by the distal channel a recording lacks: the same bars on clean recordings made without it (the smaller
#: of this and FLOOR_SCORE applies)
FLOOR_SCORE_WITHOUT: dict[str, dict[str, float]] = {
    "T_out": {"curvature_drift": 0.43, "distal_backlash": 0.05, "friction_offset": 0.42, "presliding": 0.15,
              "pretension": 0.50, "sensor_drift:T_in": 0.10, "sensor_gain:T_in": 0.42, "sensor_lag:T_in": 0.42,
              "sensor_lag:x_in": 0.50, "sensor_lag:x_out": 0.44, "sensor_offset:T_in": 0.43, "sensor_offset:x_in": 0.45,
              "stiction": 0.42, "tendon_stiffening": 0.38, "velocity_friction": 0.50}}
#: [floor^2] keyed by the distal channel a recording lacks: EXCESS_MIN for recordings made without it
EXCESS_MIN_WITHOUT: dict[str, float] = {"T_out": 4.0}
OFFSET_FLOORS = 2.0         # [T_out floors] a tension offset fitted smaller than this is not resolved

# ---- the stick-slip reading (estimator.offline.diagnosis.readings.stick_slip_ratio) ----------------------------
STICK_SLIP_RATIO = 1.4      # [-] T_in this much rougher in steady moves than in holds: stick-slip
STICK_SLIP_WEAK = 1.1       # [-] a weaker roughness, named only together with ...
STICK_SLIP_WEAK_SCORE = 0.9  # [-] ... a stiction extension whose S is below this
STICK_SLIP_WINDOW = 0.025   # [s] smoothing window of the proximal speed (at least 7 samples)
STICK_SLIP_SPEED = 1e-3     # [m/s] proximal speed above which a sample is a steady move
STICK_SLIP_HOLD = 1e-5      # [m/s] proximal speed below which a sample is a hold
STICK_SLIP_MIN_SAMPLES = 200  # [count] fewest samples of moves and of holds for the ratio to be read
STICK_SLIP_MIN_MOVE = 3.0   # [s] shortest time of steady moves for the ratio to be read
STICK_SLIP_MIN_HOLD = 1.0   # [s] shortest time of holds for the ratio to be read
RELEASE_SHARE = 0.2         # [-] a block holds a release when T_in falls this share of its range from its maximum

# ---- the distal end: held, pressed, at an end, sliding ---------------------------------------------------------
HELD_STEPS = 4.0            # [resolution steps] x_out spanning at most this many steps (quantum or noise) is held
HELD_SHARE = 0.01           # [-] ... or at most this share of x_in's travel
NEAR_HELD_SHARE = 0.1       # [-] x_out spanning less than this share of x_in's travel is pressed on a stop
AT_END_SPEED = 1e-4         # [m/s] x_in faster than this: the proximal end moves
AT_END_BAND = 0.02          # [-] share of x_out's range within which it counts as at an end of its range
AT_END_SHARE = 0.8          # [-] at an end for this share of the proximal travel: the effects below cannot show
AT_END_HIDES = ("sensor_lag:x_out",)  # effects a distal end held at an end of its range cannot show
SLIDE_SEEN = True           # the memory reads the measured distal end (where x_out moves, the whole tendon slides)
SLIDE_QUANTA = 2.0          # [quanta] x_out travel beyond this many quanta counts as motion ...
SLIDE_SIGMAS = 4.0          # [noise sigmas] ... and beyond this many times its noise ...
SLIDE_SHARE = 1e-4          # [-] ... and beyond this share of x_in's range

# ---- starts and the initial rest -------------------------------------------------------------------------------
K_RESTART = 0.6             # [-] second start of K when the base's K fell below a tenth of it
REST_MIN_S = 0.1            # [s] an initial rest shorter than this is not read for an offset
REST_RESOLUTIONS = 3.0      # [resolutions] a position reading further from zero than this at rest is off its zero

# ---- the fits ---------------------------------------------------------------------------------------------------
FIT_TOL = 1e-6              # [-] relative ftol and xtol of the refits the test block reads (step 7: errors, gain)
#: [-] relative ftol and xtol of the model choice's refinements (steps 3-6): a fit stopped there has its parameters
#: within sqrt(CHOICE_TOL) = 0.3 % (relative) of its minimum along its flattest direction, and a score S moves to
#: first order with them, against bars and ratios that the rules read in steps of 0.05 and more; the chosen model is
#: refitted at FIT_TOL before the test block
CHOICE_TOL = 1e-5
PLATEAU_BISECTIONS = 12     # [count] halvings locating the edge of a plateau in K (refinement.below_plateau)

# ---- hand motion: the rest tension and the speed-or-lag readings (estimator.offline.diagnosis.readings) ----------
REST_TENSION_SIGMAS = 10.0  # [noise sigmas] both load cells reading at least this at the initial rest: tension there
REST_TENSION_RATIO = 5.0    # [-] ... within this factor of each other (friction holds up to e^K, K <= 1.6, at rest)
HAND_WINDOW = 0.05          # [s] Savitzky-Golay window of the speed-or-lag reading's smoothing and derivatives
HAND_SLIP_SPEED = 1e-3      # [m/s] proximal speed above which a sample can be slip for the speed-or-lag reading
HAND_MIN_SLIP_S = 0.5       # [s] least slip time for the speed-or-lag reading to be read
HAND_LAG_MIN = 0.004        # [s] a delay of T_out behind the capstan ratio from this up is a lag, below it none
HAND_SPEED_MIN = 4.0        # [s/m] c_v = speed term / K from this up: friction rising with sliding speed
HAND_T_MIN = 3.0            # [-] a term of the speed-or-lag reading this many standard errors from zero is read
#: [-] at the floor, the reading names its effect when that extension's S is below this: below the base by more than
#: the model choice's own resolution (a fit stopped at CHOICE_TOL moves S by up to sqrt(CHOICE_TOL), 0.3 %), so that
#: an extension that fits the base back (its lag or its speed term at zero) is not read as one that explains something
HAND_WEAK_SCORE = 1.0 - math.sqrt(CHOICE_TOL)


def floor_scores(clean: Iterable[Mapping[str, float]], factor: float = FLOOR_FACTOR,
                 cap: float = MID_SCORE) -> dict[str, float]:
    """Per-effect bounds of FLOOR_SCORE from the candidate scores of clean recordings.

    Parameters
    ----------
    clean : iterable of mappings effect id -> validation score S [-]
        ``candidates[id].score`` of each clean recording whose base model is at the floor (structure ratio
        <= STRUCTURE_RATIO on every signal), whatever it was answered (the benchmark's ``scores``;
        ``bench_diagnosis.py --floor-table``).
    factor, cap : float
        The bound is min(cap, factor x the lowest S of the effect).

    Returns
    -------
    dict effect id -> bound [-], sorted by id.

    Raises
    ------
    ValueError
        No clean recording, a factor outside (0, 1] or a score that is not a finite number >= 0 (naming the effect).
    """
    if not 0.0 < factor <= 1.0:
        raise ValueError(f"factor must be in (0, 1], got {factor!r}")
    low: dict[str, float] = {}
    n = 0
    for scores in clean:
        n += 1
        for eid, v in scores.items():
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0):
                raise ValueError(f"clean recording {n}: score of {eid} is {v!r}, not a finite number >= 0")
            low[eid] = min(low.get(eid, math.inf), float(v))
    if n == 0:
        raise ValueError("floor_scores needs at least one clean recording")
    return {eid: min(cap, factor * low[eid]) for eid in sorted(low)}
