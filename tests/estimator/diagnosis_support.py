"""What the diagnosis tests share: the length and rate of their rig recordings, the check that a hidden effect is
named with its gain and magnitude, and a fitted model as the selection rules see it."""
import pytest

from estimator.offline.effects.catalogue import CATALOGUE, EQUIVALENT

DUR, RATE = 45.0, 500.0
# rig parameter -> fitted parameter (physical effects; a sensor effect's one parameter is its own)
FITTED = {"viscous": "c_v", "tension": "T0", "K_rate": "K_rate", "softening": "beta", "toe_tension": "T_c",
          "static_ratio": "r_s", "tension_offset": "a", "distance": "x_p", "width": "d_b"}


def check_named(eid: str, rec, res: dict, rel: float = 0.25) -> None:
    """The identifier (or, for the inseparable pairs, its equivalent), the gain and the magnitude."""
    scores = {k: round(v["score"], 3) for k, v in res["candidates"].items()}
    ok = {eid, *EQUIVALENT.get(eid, ())} if eid.startswith("sensor_gain") else {eid}
    assert res["cause"] in ok, (res["causes"], scores)
    assert res["gain"] >= 0.3, (res["gain"], scores)
    truth = rec.truth["parameters"]
    if eid.startswith("sensor_"):
        name, true = next(iter(truth.items()))
        e = CATALOGUE[res["cause"]]
        if res["cause"] != eid:         # a T_in gain g reads as a T_out gain 1/(1 + g) - 1
            true = 1.0 / (1.0 + true) - 1.0
        p = res["parameters"][e.parameters[0].name]
        assert p["effect"] == res["cause"] and p["value"] == pytest.approx(true, rel=rel), (name, truth)
    for name, true in truth.items():
        if name in FITTED:
            p = res["parameters"][FITTED[name]]
            assert p["effect"] == eid and p["value"] == pytest.approx(true, rel=rel), (name, p, truth)
    prim = res["primary_signal"]
    unit = "N" if prim == "T_out" else "m"
    assert res["extended"][f"rmse_{prim}_{unit}"] < 0.7 * res["base"][f"rmse_{prim}_{unit}"]


class _StubFit:
    """A fitted model as the rules see it: its effects, its score S and its structure ratio on T_out (floor 1)."""

    def __init__(self, ids: tuple[str, ...], S: float = 1.0, ratio: float = 1.0):
        self.effects = [CATALOGUE[i] for i in ids]
        self.S, self._ratio = S, ratio

    @property
    def ids(self) -> list[str]:
        return [e.id for e in self.effects]

    def val_mse(self) -> dict[str, float]:
        return {"T_out": self._ratio ** 2}
