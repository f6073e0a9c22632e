"""POST /api/coordinates/runway-to-radar on a real service, and the dashboard's reference
course (drawn from that endpoint) against radar_io.coordinates.transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from radar_io.benchmarks.service_load import Pty
from radar_io.coordinates.transforms import load_site, runway_to_radar
from radar_io.service.config import ServiceConfig

from .liveserver import browser, live_server, service_config, sim_server  # noqa: F401

ROUTE = "/api/coordinates/runway-to-radar"


def demo_site():
    return load_site(ServiceConfig(source="sim://").resolved_site())


def test_runway_to_radar_matches_the_python_transform(sim_server):  # noqa: F811
    rng = np.random.default_rng(3)
    xr, yr, hr = rng.uniform(-30000, 5000, 500), rng.uniform(-3000, 3000, 500), rng.uniform(0, 3000, 500)
    code, doc = sim_server.request("POST", ROUTE, {"xr_m": xr.tolist(), "yr_m": yr.tolist(),
                                                   "hr_m": hr.tolist()})
    assert code == 200, doc
    site = demo_site()
    x, y, h = runway_to_radar(xr, yr, hr, site)
    assert doc["site"] == site.name
    np.testing.assert_allclose(doc["x_m"], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(doc["y_m"], y, rtol=0, atol=1e-9)
    np.testing.assert_allclose(doc["h_m"], h, rtol=0, atol=1e-9)
    # the runway origin seen from the radar is at the (rotated) offset of the radar
    _, one = sim_server.request("POST", ROUTE, {"xr_m": [site.radar_xr_m], "yr_m": [site.radar_yr_m],
                                                "hr_m": [site.radar_hr_m]})
    assert one["x_m"][0] == pytest.approx(0, abs=1e-9) and one["h_m"][0] == pytest.approx(0)


@pytest.mark.parametrize("body, field", [
    ({"xr_m": [1.0, 2.0], "yr_m": [0.0], "hr_m": [0.0, 0.0]}, "same length"),
    ({"xr_m": [], "yr_m": [], "hr_m": []}, "xr_m"),
    ({"xr_m": [1.0], "yr_m": ["north"], "hr_m": [0.0]}, "yr_m"),
    ({"xr_m": [1.0], "yr_m": [0.0]}, "hr_m"),
    ({"xr_m": [0.0] * 10_001, "yr_m": [0.0] * 10_001, "hr_m": [0.0] * 10_001}, "xr_m"),
])
def test_bad_bodies_are_422_naming_the_field(sim_server, body, field):  # noqa: F811
    code, doc = sim_server.request("POST", ROUTE, body)
    assert code == 422
    assert field in str(doc["detail"])


def test_non_finite_values_are_refused(sim_server):  # noqa: F811
    import urllib.request

    req = urllib.request.Request(sim_server.base + ROUTE, method="POST",
                                 data=b'{"xr_m": [NaN], "yr_m": [0], "hr_m": [0]}',
                                 headers={"Content-Type": "application/json"})
    with pytest.raises(urllib.error.HTTPError) as exc:
        urllib.request.urlopen(req, timeout=10)
    assert exc.value.code == 422
    assert "xr_m[0] is not a finite number" in exc.value.read().decode()


def test_without_a_site_the_route_says_so(tmp_path):
    pty = Pty()  # a serial source has no default site
    try:
        with live_server(service_config(tmp_path, source=pty.path)) as srv:
            code, doc = srv.request("POST", ROUTE, {"xr_m": [0.0], "yr_m": [0.0], "hr_m": [0.0]})
            assert code == 404 and "no radar site configured" in str(doc["detail"])
    finally:
        pty.close()


def test_dashboard_reference_course_comes_from_the_api(sim_server, browser):  # noqa: F811
    browser.navigate(sim_server.base + "/")
    browser.wait_for("radarState.ref !== null", 10)
    ref = browser.eval("radarState.ref")
    x, y, _ = runway_to_radar(np.array([-20000.0, 0.0, 3000.0]), np.zeros(3), np.zeros(3), demo_site())
    for k, name in enumerate(("from", "td", "to")):
        assert math.isclose(ref[name]["x"], x[k], abs_tol=1e-9)
        assert math.isclose(ref[name]["y"], y[k], abs_tol=1e-9)
