"""Radar bias statistics (calibration.md §8) on hand-made tables."""

from __future__ import annotations

import math

import numpy as np
import pytest

from radar_io.calibration import bias_calibration, bias_statistics, photo_to_radar, wrap_deg


def pstd(values):
    m = sum(values) / len(values)
    return math.sqrt(sum((v - m) ** 2 for v in values) / len(values))


def test_wrap_to_minus_180_plus_180():
    np.testing.assert_allclose(wrap_deg([0.0, 359.96, -359.96, 180.0, -180.0, 190.0, -190.0, 540.0]),
                               [0.0, -0.04, 0.04, 180.0, 180.0, -170.0, 170.0, 180.0], atol=1e-12)


def test_photo_position_to_sr_el_az():
    # X north, Y east, Z down: H = −Z
    sr, el, az = photo_to_radar(np.array([3000.0, 0.0, 2000.0]), np.array([4000.0, -500.0, 0.0]),
                                np.array([0.0, -500.0, -2000.0]))
    np.testing.assert_allclose(sr, [5000.0, math.sqrt(500_000), 2000.0 * math.sqrt(2)])
    np.testing.assert_allclose(el, [0.0, 45.0, 45.0], atol=1e-12)
    np.testing.assert_allclose(az, [math.degrees(math.atan2(4, 3)), 270.0, 0.0], atol=1e-12)


def test_per_group_and_combined_statistics():
    # flight A: AZ straddles north (photo 359.98 vs radar 0.02 → −0.04, photo 0.01 vs radar 359.97 → +0.04)
    groups = ["A", "A", "A", "B", "B"]
    photo_sr = [10000.0, 10010.0, 10020.0, 8000.0, 8100.0]
    radar_sr = [9995.0, 10004.0, 10013.0, 7997.0, 8099.0]        # ΔSR: 5, 6, 7 | 3, 1
    photo_el = [5.00, 5.10, 5.20, 3.00, 3.05]
    radar_el = [4.98, 5.07, 5.21, 3.04, 3.05]                    # ΔEL: .02, .03, −.01 | −.04, 0
    photo_az = [359.98, 0.01, 10.00, 120.00, 121.00]
    radar_az = [0.02, 359.97, 9.97, 120.10, 121.00]              # ΔAZ: −.04, .04, .03 | −.10, 0
    out = bias_statistics(groups, (photo_sr, photo_el, photo_az), (radar_sr, radar_el, radar_az))
    a, b, c = out["groups"]["A"], out["groups"]["B"], out["combined"]
    assert list(out["groups"]) == ["A", "B"]
    assert a["n"] == 3 and b["n"] == 2 and c["n"] == 5
    assert a["dsr_m"]["mean"] == pytest.approx(6.0) and a["dsr_m"]["std"] == pytest.approx(math.sqrt(2 / 3))
    assert b["dsr_m"]["mean"] == pytest.approx(2.0) and b["dsr_m"]["std"] == pytest.approx(1.0)
    assert a["del_deg"]["mean"] == pytest.approx(0.04 / 3)
    assert a["del_deg"]["std"] == pytest.approx(pstd([0.02, 0.03, -0.01]))
    assert b["del_deg"]["mean"] == pytest.approx(-0.02) and b["del_deg"]["std"] == pytest.approx(0.02)
    assert a["daz_deg"]["mean"] == pytest.approx(0.01)
    assert a["daz_deg"]["std"] == pytest.approx(pstd([-0.04, 0.04, 0.03]))
    assert b["daz_deg"]["mean"] == pytest.approx(-0.05) and b["daz_deg"]["std"] == pytest.approx(0.05)
    # combined: mean of the per-flight means and mean of the per-flight stds (not the pooled figures)
    assert c["dsr_m"]["mean"] == pytest.approx((6.0 + 2.0) / 2)
    assert c["dsr_m"]["std"] == pytest.approx((math.sqrt(2 / 3) + 1.0) / 2)
    assert c["del_deg"]["mean"] == pytest.approx((0.04 / 3 - 0.02) / 2)
    assert c["daz_deg"]["mean"] == pytest.approx((0.01 - 0.05) / 2)
    assert c["daz_deg"]["std"] == pytest.approx((pstd([-0.04, 0.04, 0.03]) + 0.05) / 2)
    assert c["dsr_m"]["mean"] != pytest.approx(np.mean([5, 6, 7, 3, 1]))  # the pooled mean (4.4) differs


def test_calibration_set_from_statistics():
    out = bias_statistics(["F1", "F1"], ([100.0, 102.0], [1.0, 1.2], [0.0, 359.9]),
                          ([99.0, 100.0], [1.1, 1.1], [359.9, 0.1]))
    cal = bias_calibration(out, cal_id="flight-1", provenance={"input": "x.csv"})
    assert cal.dsr_m == pytest.approx(1.5)
    assert cal.del_deg == pytest.approx(0.0, abs=1e-12)
    assert cal.daz_deg == pytest.approx((0.1 - 0.2) / 2)  # 0 − 359.9 → +0.1, 359.9 − 0.1 → −0.2
    assert cal.statistics == out and cal.id == "flight-1" and cal.created_utc.endswith("Z")
