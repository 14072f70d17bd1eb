"""The recording demo's checks read as sentences with the figure and the bound, on each recording format."""
from __future__ import annotations

from live.demo.recording import AGREEMENT_DEG, AGREEMENT_FS, ANGLE_RMSE_BOUND_DEG, TORQUE_RMSE_BOUND, recording_checks
from live.demo.run import verdict_lines


def test_mrd_checks_name_the_figures_and_the_bounds() -> None:
    checks = recording_checks({"torque_rmse_fs": 0.0305, "live_minus_offline_fs": -0.0002})
    assert checks == {
        f"jaw torque live vs measured: RMSE 0.0305 FS, bound {TORQUE_RMSE_BOUND} FS": True,
        f"jaw torque live vs offline (same model, same cycles): |live - offline| 0.0002 FS, "
        f"bound {AGREEMENT_FS} FS": True}
    lines = verdict_lines({"checks": checks})
    assert lines[0].startswith("[PASS] jaw torque live vs measured: RMSE 0.0305 FS")
    assert not any("_" in line for line in lines)


def test_kaist_checks_fail_beyond_the_bounds() -> None:
    checks = recording_checks({"format": "kaist", "angle_rmse_deg": 6.0, "live_minus_offline_deg": 0.2})
    assert checks == {
        f"distal angle live vs measured: RMSE 6.00 deg, bound {ANGLE_RMSE_BOUND_DEG} deg": False,
        f"distal angle live vs offline (same model, same samples): |live - offline| 0.200 deg, "
        f"bound {AGREEMENT_DEG} deg": False}


def test_tendon_check_and_nan() -> None:
    checks = recording_checks({"format": "csv", "live_minus_offline_fs": float("nan")})
    assert list(checks.values()) == [False]
    (name,) = checks
    assert name.startswith("distal tension live vs offline") and f"bound {AGREEMENT_FS} FS" in name
