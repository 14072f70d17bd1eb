"""The result of a single-tendon diagnosis as typed objects, and their JSON form.

:class:`Diagnosis` is what :func:`estimator.offline.diagnosis.selection.diagnose_recording` returns;
:meth:`Diagnosis.to_json` writes the JSON object of :func:`estimator.offline.diagnosis.selection.diagnose` (the keys
documented there, which ``teleop analyze`` prints and saves) and :meth:`Diagnosis.from_json` reads one back (a saved
``diagnosis.json``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["Candidate", "StickSlip", "RestOffset", "Model", "Diagnosis", "as_diagnosis"]


@dataclass
class Candidate:
    """One extension fitted alone on the folds of the training block (never on the test block).

    ``validation``: {"rmse_T_out_N", "rmse_x_out_m"} mean over the judged folds [N], [m] (None: signal absent);
    ``score`` S [-] against the base (the worse fold, or the one fold that judges); ``penalised_score`` S + PENALTY x
    its parameters; ``parameters`` name -> {value, unit, effect} on the first fold; ``fold_values`` and
    ``fold_scores`` per fold computed; ``scored_on`` which fold decided, in words.
    """

    validation: dict[str, float | None]
    score: float
    penalised_score: float
    accepted: bool
    equivalent: list[str]
    parameters: dict[str, dict]
    fold_values: list[dict[str, float]]
    fold_scores: list[float]
    scored_on: str

    def to_json(self) -> dict[str, Any]:
        return {**{f"validation_{k}": v for k, v in self.validation.items()}, "score": self.score,
                "penalised_score": self.penalised_score, "accepted": self.accepted, "equivalent": self.equivalent,
                "parameters": self.parameters, "fold_values": self.fold_values, "fold_scores": self.fold_scores,
                "scored_on": self.scored_on}

    @classmethod
    def from_json(cls, d: dict) -> Candidate:
        return cls({k[len("validation_"):]: v for k, v in d.items() if k.startswith("validation_")}, d["score"],
                   d["penalised_score"], d["accepted"], d["equivalent"], d["parameters"], d["fold_values"],
                   d["fold_scores"], d["scored_on"])


@dataclass
class StickSlip:
    """The stick-slip reading: ``ratio`` [-] (None: unreadable), whether it ``named`` stiction, by the ``weak``
    rule, the ids it ``overruled``, and the ``samples`` it read (the training block)."""

    ratio: float | None
    named: bool
    weak: bool
    overruled: list[str]
    samples: dict

    def to_json(self) -> dict[str, Any]:
        return {"ratio": self.ratio, "named": self.named, "weak": self.weak, "overruled": self.overruled,
                "samples": self.samples}


@dataclass
class RestOffset:
    """The reading at the initial rest: the offset id an encoder ``reads`` (or None), whether it was ``named``, and
    |median| of x_in and x_out there [m] (x_out None when absent)."""

    reads: str | None
    named: bool
    x_in_m: float
    x_out_m: float | None

    def to_json(self) -> dict[str, Any]:
        return {"reads": self.reads, "named": self.named, "x_in_m": self.x_in_m, "x_out_m": self.x_out_m}


@dataclass
class Model:
    """A model refitted on the training block: its extension ids, values (K, route shares, parameters, held
    settings) and compliance L/EA [m/N]; enough to run it again
    (:func:`estimator.offline.diagnosis.fit.predictions`)."""

    effects: list[str]
    values: dict[str, float]
    compliance: float

    def to_json(self) -> dict[str, Any]:
        return {"effects": self.effects, "values": self.values, "compliance": self.compliance}


@dataclass
class Diagnosis:
    """What the base model gets wrong on one recording, the effect that explains it and the held-out gain.

    The fields are the keys of the JSON (:func:`estimator.offline.diagnosis.selection.diagnose` documents each);
    ``candidates``, ``stick_slip``, ``rest_offset``, ``model`` and ``base_model`` are typed, the others plain
    JSON-ready dicts and lists.
    """

    cause: str
    causes: list[str]
    equivalent: list[str]
    base: dict[str, float | None]
    extended: dict[str, float | None]
    gain: float
    primary_signal: str
    parameters: dict[str, dict]
    candidates: dict[str, Candidate]
    split: dict
    noise: dict[str, float]
    structure: dict[str, dict[str, float]]
    stick_slip: StickSlip
    rest_offset: RestOffset
    model: Model
    base_model: Model
    settings: dict
    elapsed_s: float
    extra: dict = field(default_factory=dict)
    screened: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The JSON object (a dict of str, numbers, lists, dicts and None), keys in the documented order; keys a
        caller added to a loaded result (``extra``: file, n_samples, ...) come last."""
        return {"cause": self.cause, "causes": self.causes, "equivalent": self.equivalent, "base": self.base,
                "extended": self.extended, "gain": self.gain, "primary_signal": self.primary_signal,
                "parameters": self.parameters,
                "candidates": {k: c.to_json() for k, c in self.candidates.items()}, "screened": self.screened,
                "split": self.split,
                "noise": self.noise, "structure": self.structure, "stick_slip": self.stick_slip.to_json(),
                "rest_offset": self.rest_offset.to_json(), "model": self.model.to_json(),
                "base_model": self.base_model.to_json(), "settings": self.settings, "elapsed_s": self.elapsed_s,
                **self.extra}

    @classmethod
    def from_json(cls, d: dict) -> Diagnosis:
        """The typed result of a JSON object written by :meth:`to_json`.

        Raises
        ------
        KeyError
            A key of the documented result is missing (naming it).
        """
        known = {"cause", "causes", "equivalent", "base", "extended", "gain", "primary_signal", "parameters",
                 "candidates", "split", "noise", "structure", "stick_slip", "rest_offset", "model", "base_model",
                 "settings", "elapsed_s"}
        missing = sorted(known - set(d))
        if missing:
            raise KeyError(f"not a diagnosis result: key {missing[0]!r} missing")
        return cls(d["cause"], list(d["causes"]), list(d["equivalent"]), d["base"], d["extended"], d["gain"],
                   d["primary_signal"], d["parameters"],
                   {k: Candidate.from_json(c) for k, c in d["candidates"].items()}, d["split"], d["noise"],
                   d["structure"], StickSlip(**d["stick_slip"]), RestOffset(**d["rest_offset"]),
                   Model(**d["model"]), Model(**d["base_model"]), d["settings"], d["elapsed_s"],
                   {k: v for k, v in d.items() if k not in known | {"screened"}}, dict(d.get("screened", {})))


def as_diagnosis(result: Diagnosis | dict) -> Diagnosis:
    """A :class:`Diagnosis` from either form (the typed object, or its JSON dict as saved or returned by
    :func:`estimator.offline.diagnosis.selection.diagnose`)."""
    return result if isinstance(result, Diagnosis) else Diagnosis.from_json(result)
