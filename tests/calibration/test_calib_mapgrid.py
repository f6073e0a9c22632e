"""Map grid → radar local frame (calibration.md §7, appendix C)."""

from __future__ import annotations

import numpy as np
import pymap3d
import pyproj
import pytest

from radar_io.calibration import (
    CalibrationError,
    fit_quadratic_model,
    gauss_kruger_series,
    japan_zone_crs,
    map_to_local,
)

ROMAN = ["I", "II", "III", "IV", "V", "VI", "VII", "VIII", "IX", "X", "XI", "XII", "XIII", "XIV", "XV",
         "XVI", "XVII", "XVIII", "XIX"]
# zone IX origin 36°00′N 139°50′E
LAT0, LON0 = 36.0, 139.0 + 50.0 / 60.0
SITE_LL = (35.75, 139.95, 20.0)  # a radar site in zone IX (lat, lon deg; height m)


def test_zone_codes_are_the_named_crs():
    assert japan_zone_crs(9, "tokyo") == "EPSG:30169"
    assert japan_zone_crs(9, "jgd2000") == "EPSG:2451"
    assert japan_zone_crs(9, "jgd2011") == "EPSG:6677"
    for datum, label in (("tokyo", "Tokyo"), ("jgd2000", "JGD2000"), ("jgd2011", "JGD2011")):
        for zone in range(1, 20):
            crs = pyproj.CRS.from_user_input(japan_zone_crs(zone, datum))
            assert crs.name == f"{label} / Japan Plane Rectangular CS {ROMAN[zone - 1]}", crs.name
    ix = pyproj.CRS.from_epsg(30169)
    assert ix.ellipsoid.semi_major_metre == 6377397.155
    assert ix.ellipsoid.inverse_flattening == pytest.approx(299.152813, abs=1e-6)
    with pytest.raises(CalibrationError):
        japan_zone_crs(20, "tokyo")
    with pytest.raises(CalibrationError):
        japan_zone_crs(9, "wgs84")


@pytest.mark.parametrize("epsg", ["EPSG:30169", "EPSG:6677"])
def test_gauss_kruger_series_matches_pyproj(epsg):
    crs = pyproj.CRS.from_user_input(epsg)
    ell = crs.ellipsoid
    rng = np.random.default_rng(0)
    lat = rng.uniform(LAT0 - 1.0, LAT0 + 1.0, 50)
    lon = rng.uniform(LON0 - 0.8, LON0 + 0.8, 50)
    east, north = pyproj.Transformer.from_crs(crs.geodetic_crs, crs, always_xy=True).transform(lon, lat)
    x, y = gauss_kruger_series(lat, lon, LAT0, LON0, ell.semi_major_metre, 1.0 / ell.inverse_flattening)
    assert np.max(np.abs(x - north)) < 1e-3
    assert np.max(np.abs(y - east)) < 1e-3


@pytest.mark.parametrize("epsg,ellipsoid",
                         [("EPSG:30169", "bessel"), ("EPSG:2451", "grs80"), ("EPSG:6677", "grs80")])
def test_local_ned_matches_pymap3d(epsg, ellipsoid):
    crs = pyproj.CRS.from_user_input(epsg)
    fwd = pyproj.Transformer.from_crs(crs.geodetic_crs, crs, always_xy=True)
    rng = np.random.default_rng(1)
    lat = SITE_LL[0] + rng.uniform(-0.1, 0.1, 30)
    lon = SITE_LL[1] + rng.uniform(-0.1, 0.1, 30)
    h = rng.uniform(0.0, 800.0, 30)
    e, n = fwd.transform(lon, lat)
    se, sn = fwd.transform(SITE_LL[1], SITE_LL[0])
    conv = map_to_local(np.column_stack([n, e, h]), np.array([sn, se, SITE_LL[2]]), epsg)
    ell = pymap3d.Ellipsoid.from_name(ellipsoid)
    expected = np.column_stack(pymap3d.geodetic2ned(lat, lon, h, *SITE_LL, ell=ell))
    assert np.max(np.abs(conv.ned_m - expected)) < 1e-3
    np.testing.assert_allclose(conv.site_geodetic, SITE_LL, atol=1e-9)
    # a constant geoid height shifts every height equally: local coordinates change only by ppm
    shifted = map_to_local(np.column_stack([n, e, h]), np.array([sn, se, SITE_LL[2]]), epsg,
                           geoid_height_m=40.0)
    assert 1e-4 < np.max(np.abs(shifted.ned_m - conv.ned_m)) < 0.1


def _course(half_width_m, heading_deg=30.0, n=40, relief_m=60.0):
    crs = pyproj.CRS.from_epsg(30169)
    to_grid = pyproj.Transformer.from_crs(crs.geodetic_crs, crs, always_xy=True)
    se, sn = to_grid.transform(SITE_LL[1], SITE_LL[0])
    rng = np.random.default_rng(2)
    along = rng.uniform(0.0, 10000.0, n)
    across = rng.uniform(-half_width_m, half_width_m, n)
    a = np.radians(heading_deg)
    pts = np.column_stack([sn + along * np.cos(a) - across * np.sin(a),
                           se + along * np.sin(a) + across * np.cos(a),
                           30.0 + rng.uniform(0.0, relief_m, n)])
    return map_to_local(pts, np.array([sn, se, SITE_LL[2]]), "EPSG:30169")


def test_quadratic_model_over_a_10_km_course():
    conv = _course(1000.0)
    d = conv.differences_m
    # raw differences of the order of 10 m (grid convergence, scale factor, earth curvature)
    assert 5.0 < np.max(np.abs(d[:, :2])) < 30.0
    assert 5.0 < np.max(np.abs(d[:, 2])) < 10.0
    model = fit_quadratic_model(conv.map_relative_m[:, :2], d)
    res = np.max(np.abs(model.residuals_m), axis=0)
    # the source: ±20 mm (X), ±1 mm (Y), 0.1 mm (H) after the fit
    assert res[0] < 0.05 and res[1] < 0.05 and res[2] < 1e-3, res
    np.testing.assert_allclose(model.predict(conv.map_relative_m[:, :2]), d - model.residuals_m, atol=1e-12)


def test_quadratic_model_on_a_narrow_level_course_is_millimetric():
    # the model has no height term: a point h above the ellipsoid at distance d leans h·d/R
    # (≈ 9 cm for 60 m at 10 km), which is what limits the fit above; on level ground it vanishes
    conv = _course(100.0, heading_deg=0.0, relief_m=0.0)
    model = fit_quadratic_model(conv.map_relative_m[:, :2], conv.differences_m)
    assert np.max(np.abs(model.residuals_m)) < 1e-3


def test_bad_crs_and_points():
    site = np.array([-27000.0, 10000.0, 20.0])
    with pytest.raises(CalibrationError, match="not a projected"):
        map_to_local(site[None, :], site, "EPSG:4301")
    with pytest.raises(CalibrationError, match="unknown coordinate reference system"):
        map_to_local(site[None, :], site, "EPSG:99999999")
    with pytest.raises(CalibrationError, match="at least 5 points"):
        fit_quadratic_model(np.zeros((4, 2)), np.zeros((4, 3)))
