"""Coordinates (radar-interface.md §5) cross-checked against pymap3d and pyproj."""

from __future__ import annotations

import numpy as np
import pymap3d
import pytest
from pyproj import Transformer

from radar_io.coordinates.transforms import geodetic, load_site, radar_sea, radar_xyh, runway_xyh
from radar_io.decoding.decoders import decode_bytes
from radar_io.encoding.rdr1 import encode_frames, raw_words
from radar_io.wirespec.frame import spec_dir

rng = np.random.default_rng(42)
SR = rng.uniform(0, 65000, 2000)
EL = rng.uniform(-5, 89, 2000)
AZ = rng.uniform(0, 360, 2000)
SITE = load_site(spec_dir() / "sites" / "demo.toml")


def test_radar_rectangular_matches_pymap3d_aer2enu():
    x, y, h = radar_xyh(SR, EL, AZ)
    e, n, u = pymap3d.aer2enu(AZ, EL, SR)
    np.testing.assert_allclose(x, n, atol=1e-8)
    np.testing.assert_allclose(y, e, atol=1e-8)
    np.testing.assert_allclose(h, u, atol=1e-8)


def test_inverse_round_trips_and_folds_azimuth():
    sr, el, az = radar_sea(*radar_xyh(SR, EL, AZ))
    np.testing.assert_allclose(sr, SR, atol=1e-8)
    np.testing.assert_allclose(el, EL, atol=1e-10)
    np.testing.assert_allclose(az, AZ, atol=1e-10)
    assert radar_sea(-1.0, -1.0, 0.0)[2] == pytest.approx(225.0)
    assert radar_sea(-1.0, 0.0, 0.0)[2] == pytest.approx(180.0)


def test_runway_frame_is_a_rotation_by_the_runway_heading_plus_offset():
    xr, yr, hr = runway_xyh(SR, EL, AZ, SITE)
    x, y, h = radar_xyh(SR, EL, AZ)
    p = np.radians(SITE.runway_heading_deg)
    # an independent statement: X_r axis = unit vector of heading, Y_r = 90 deg to its right
    ax, ay = np.array([np.cos(p), np.sin(p)]), np.array([-np.sin(p), np.cos(p)])
    np.testing.assert_allclose(xr, x * ax[0] + y * ax[1] + SITE.radar_xr_m, atol=1e-7)
    np.testing.assert_allclose(yr, x * ay[0] + y * ay[1] + SITE.radar_yr_m, atol=1e-7)
    np.testing.assert_allclose(hr, h + SITE.radar_hr_m, atol=1e-9)
    # a target straight down the runway heading from the radar is on the X_r axis through it
    xr1, yr1, _ = runway_xyh(1000.0, 0.0, SITE.runway_heading_deg, SITE)
    assert xr1 == pytest.approx(1000.0 + SITE.radar_xr_m) and yr1 == pytest.approx(SITE.radar_yr_m)


def test_runway_to_radar_inverts_the_runway_frame():
    from radar_io.coordinates.transforms import runway_to_radar

    x, y, h = runway_to_radar(*runway_xyh(SR, EL, AZ, SITE), SITE)
    x0, y0, h0 = radar_xyh(SR, EL, AZ)
    np.testing.assert_allclose(x, x0, atol=1e-7)
    np.testing.assert_allclose(y, y0, atol=1e-7)
    np.testing.assert_allclose(h, h0, atol=1e-9)


def test_geodetic_matches_an_independent_pyproj_ecef_chain():
    lat, lon, hae = geodetic(SR, EL, AZ, SITE)
    to_ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    x0, y0, z0 = to_ecef.transform(SITE.lon_deg, SITE.lat_deg, SITE.h_m)
    L, lam = np.radians(SITE.lat_deg), np.radians(SITE.lon_deg)
    north = np.array([-np.sin(L) * np.cos(lam), -np.sin(L) * np.sin(lam), np.cos(L)])  # (C-9)
    east = np.array([-np.sin(lam), np.cos(lam), 0.0])
    up = np.array([np.cos(L) * np.cos(lam), np.cos(L) * np.sin(lam), np.sin(L)])
    x, y, h = radar_xyh(SR, EL, AZ)
    ecef = np.array([x0, y0, z0])[:, None] + np.outer(north, x) + np.outer(east, y) + np.outer(up, h)
    lon2, lat2, h2 = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(*ecef)
    np.testing.assert_allclose(lat, lat2, atol=1e-9)   # ~0.1 mm
    np.testing.assert_allclose(lon, lon2, atol=1e-9)
    np.testing.assert_allclose(hae, h2, atol=1e-3)


def test_curvature_drop_matches_the_prime_vertical_circle():
    """A horizontal line of sight to the east rises above the ellipsoid as the earth curves
    away (§5). Independent reference: the prime-vertical normal section is, over 25 km, a
    circle of radius N(lat) + h to well under a millimetre, so the rise is sqrt(R² + d²) - R."""
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    n = a / np.sqrt(1 - e2 * np.sin(np.radians(SITE.lat_deg)) ** 2)
    r = n + SITE.h_m
    d = np.array([1000.0, 5000.0, 25000.0])
    _, _, hae = geodetic(d, 0.0, 90.0, SITE)
    np.testing.assert_allclose(hae - SITE.h_m, np.sqrt(r * r + d * d) - r, atol=2e-3)


def test_decoder_site_columns_match_the_functions(spec):
    vals = {"seq": np.arange(5), "tod_s": np.zeros(5), "sr_m": SR[:5], "dsr_m": np.zeros(5),
            "el_deg": EL[:5], "del_deg": np.zeros(5), "az_deg": AZ[:5], "daz_deg": np.zeros(5),
            "status_raw": np.array([5, 5, 5, 1, 5])}
    b = decode_bytes(encode_frames(spec, raw_words(spec, vals)), site=SITE)
    lat, _lon, _hae = geodetic(b["sr_c_m"], b["el_c_deg"], b["az_c_deg"], SITE)
    np.testing.assert_array_equal(b["lat_deg"], lat)
    assert np.isnan(b["lat_deg"][3]) and np.isnan(b["xr_m"][3])
    from radar_io.decoding.decoders import FrameDecoder

    m = FrameDecoder(spec, site=SITE).decode(encode_frames(spec, raw_words(spec, vals))[:24])
    assert m["lat_deg"] == pytest.approx(lat[0], abs=1e-12)
    assert m["xr_m"] == pytest.approx(b["xr_m"][0], abs=1e-6)
