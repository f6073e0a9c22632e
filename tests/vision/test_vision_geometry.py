"""Runway-vision geometry (spec runway-vision.md §1–§3) against an independent forward projector.

Ground truth comes from projecting earth-frame points with eq. (1)–(2) only; the
inverse formulas (eq. 3–4, 9, 17–20 and solve_pose) must reproduce it.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radar_io.vision import pose_equations as g

D = 22.5  # runway half-width [m]
F = 554.2562584220408  # 640 px across a 60 deg field of view


def _grid() -> dict[str, np.ndarray]:
    """Every combination over the envelope: bank ±20, pitch -10..5, yaw ±10 deg, height 5..500 m,
    lateral ±40 m."""
    banks = np.radians([-20, -7, 0, 11, 20])
    pitches = np.radians([-10, -4.5, 0, 2, 5])
    yaws = np.radians([-10, -3, 0, 6, 10])
    heights = [5, 12, 40, 150, 320, 500]
    laterals = [-40, -22.5, -5, 0, 17, 22.5, 40]  # includes camera straight above an edge
    combos = np.array(list(itertools.product(banks, pitches, yaws, heights, laterals)), dtype=float)
    return dict(zip(("bank", "pitch", "yaw", "h", "y"), combos.T, strict=True))


def _horizon_from_projection(bank, pitch, yaw, f=F):
    """Horizon through the images of two horizontal directions (points at infinity of z = 0)."""
    pts = []
    for da in (-0.35, 0.4):
        d = np.stack([np.cos(yaw + da), np.sin(yaw + da), np.zeros_like(yaw)], -1)
        x, y, _ = g.project_points(d, np.zeros_like(d), bank, pitch, yaw, f)
        pts.append((x, y))
    return g.line_through(*pts)


def _edge_lines_by_points(bank, pitch, yaw, y0, h, d=D, f=F):
    """Right and left edge lines through two projected ground points each (no point at infinity)."""
    cam = np.stack([np.zeros_like(y0), y0, -h], -1)
    out = []
    for side in (1.0, -1.0):
        near = 3.0 * (h + np.abs(y0) + d)
        pts = []
        for x in (near, 5.0 * near):
            p = np.stack([x, np.full_like(x, side * d), np.zeros_like(x)], -1)
            px, py, depth = g.project_points(p, cam, bank, pitch, yaw, f)
            assert np.all(depth > 0)
            pts.append((px, py))
        out.append(g.line_through(*pts))
    return out[0], out[1]


# ------------------------------------------------------------------------ frames
def test_rotation_matrix_is_calibration_c_ij():
    bank, pitch, yaw = 0.3, -0.2, 0.7

    def rx(a):
        return np.array([[1, 0, 0], [0, math.cos(a), math.sin(a)], [0, -math.sin(a), math.cos(a)]])

    def ry(a):
        return np.array([[math.cos(a), 0, -math.sin(a)], [0, 1, 0], [math.sin(a), 0, math.cos(a)]])

    def rz(a):
        return np.array([[math.cos(a), math.sin(a), 0], [-math.sin(a), math.cos(a), 0], [0, 0, 1]])

    c = g.rotation_matrix(bank, pitch, yaw)
    np.testing.assert_allclose(c, rx(bank) @ ry(pitch) @ rz(yaw), atol=1e-15)
    assert c[0, 2] == pytest.approx(-math.sin(pitch))  # c13 = -sin(theta)
    assert c[1, 2] == pytest.approx(math.sin(bank) * math.cos(pitch))  # c23
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-15)


def test_image_y_is_up_while_pixel_rows_go_down():
    pp = (319.5, 239.5)
    x, y = g.pixel_to_image(400.0, 100.0, pp)  # right of and above the principal point
    assert x > 0 and y > 0
    u, v = g.image_to_pixel(x, y, pp)
    assert (u, v) == (400.0, 100.0)
    # a point above the horizon of a level camera projects to y' > 0, i.e. a smaller pixel row
    px, py, _ = g.project_points([100.0, 0.0, -60.0], [0.0, 0.0, -50.0], 0.0, 0.0, 0.0, F)
    assert py > 0 and g.image_to_pixel(px, py, pp)[1] < pp[1]
    # line conversions keep the point set
    line_px = g.line_through((10.0, 20.0), (300.0, 170.0))
    line_img = g.pixel_line_to_image(line_px, pp)
    xi, yi = g.pixel_to_image(10.0, 20.0, pp)
    assert g.point_line_distance(line_img, xi, yi) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(g.normalise_lines(g.image_line_to_pixel(line_img, pp)), line_px, atol=1e-12)


# ------------------------------------------------------------------------ spec equations
def test_horizon_eq9_and_vanishing_point_eq3_4_match_projection():
    k = _grid()
    hz = g.horizon_line(k["bank"], k["pitch"], F)
    hz_proj = _horizon_from_projection(k["bank"], k["pitch"], k["yaw"])
    # same line: compare slopes and intercepts (eq. 9: y' = tan(phi) x' - f tan(theta) / cos(phi))
    for line in (hz, hz_proj):
        slope, icpt = -line[..., 0] / line[..., 1], -line[..., 2] / line[..., 1]
        np.testing.assert_allclose(slope, np.tan(k["bank"]), atol=1e-12)
        np.testing.assert_allclose(icpt, -F * np.tan(k["pitch"]) / np.cos(k["bank"]), atol=1e-9)
    # eq. 3-4: the runway direction's point at infinity ...
    vx, vy = g.vanishing_point(k["bank"], k["pitch"], k["yaw"], F)
    along = np.stack([np.ones_like(k["h"]), 0 * k["h"], 0 * k["h"]], -1)
    px, py, _ = g.project_points(along, np.zeros_like(along), k["bank"], k["pitch"], k["yaw"], F)
    np.testing.assert_allclose(vx, px, atol=1e-9)
    np.testing.assert_allclose(vy, py, atol=1e-9)
    # ... lies on the horizon, and far edge points converge to it
    np.testing.assert_allclose(g.point_line_distance(hz, vx, vy), 0.0, atol=1e-9)
    cam = np.stack([0 * k["h"], k["y"], -k["h"]], -1)
    far = np.stack([np.full_like(k["h"], 1e9), np.full_like(k["h"], D), 0 * k["h"]], -1)
    fx, fy, _ = g.project_points(far, cam, k["bank"], k["pitch"], k["yaw"], F)
    np.testing.assert_allclose(fx, vx, atol=1e-3)
    np.testing.assert_allclose(fy, vy, atol=1e-3)
    # bank-corrected vanishing point: y'' = -f tan(theta), x'' = -f tan(psi) / cos(theta)
    xb, yb = g.bank_correct(vx, vy, k["bank"])
    np.testing.assert_allclose(yb, -F * np.tan(k["pitch"]), atol=1e-9)
    np.testing.assert_allclose(xb, -F * np.tan(k["yaw"]) / np.cos(k["pitch"]), atol=1e-9)


def test_edge_slopes_eq17_18_and_position_eq19_20():
    k = _grid()
    right, left = _edge_lines_by_points(k["bank"], k["pitch"], k["yaw"], k["y"], k["h"])

    def measured_slope(line):  # dy''/dx'' in the bank-corrected image
        nx, ny = g.bank_correct(line[..., 0], line[..., 1], k["bank"])
        with np.errstate(divide="ignore"):
            return -nx / ny

    k1, k2 = g.edge_slopes(k["pitch"], k["yaw"], k["y"], -k["h"], D)
    m1, m2 = measured_slope(right), measured_slope(left)
    finite = (np.abs(k1) < 1e6) & (np.abs(k2) < 1e6)  # vertical edges (k infinite) are checked via 1/k
    assert finite.sum() > 0.8 * finite.size
    np.testing.assert_allclose(m1[finite], k1[finite], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(m2[finite], k2[finite], rtol=1e-9, atol=1e-9)
    with np.errstate(divide="ignore"):
        np.testing.assert_allclose(1 / m1, 1 / k1, atol=1e-9)
        np.testing.assert_allclose(1 / m2, 1 / k2, atol=1e-9)
    # eq. 19-20 recover the camera position from the measured slopes
    y0, z0 = g.position_from_slopes(m1[finite], m2[finite], k["pitch"][finite], k["yaw"][finite], D)
    np.testing.assert_allclose(z0, -k["h"][finite], rtol=1e-9)
    np.testing.assert_allclose(y0, k["y"][finite], atol=1e-9 * 500)
    # the inverse-slope form agrees everywhere, including straight above an edge
    with np.errstate(divide="ignore"):
        y0i, z0i = g.position_from_inverse_slopes(1 / m1, 1 / m2, k["pitch"], k["yaw"], D)
    np.testing.assert_allclose(z0i, -k["h"], rtol=1e-9)
    np.testing.assert_allclose(y0i, k["y"], atol=1e-9 * 500)


def test_eq15_16_reductions_at_zero_pitch_and_yaw():
    for y0, h in [(0.0, 50.0), (10.0, 5.0), (-30.0, 300.0)]:
        k1, k2 = g.edge_slopes(0.0, 0.0, y0, -h, D)
        assert D * (k1 + k2) / (k1 - k2) == pytest.approx(y0, abs=1e-9)  # (15)
        assert -2 * D * k1 * k2 / (k1 - k2) == pytest.approx(-h, rel=1e-12)  # (16): z0


# ------------------------------------------------------------------------ full inverse
def test_solve_pose_round_trips_over_the_envelope():
    k = _grid()
    right, left = g.runway_edge_lines(k["bank"], k["pitch"], k["yaw"], k["y"], k["h"], D, F)
    hz = _horizon_from_projection(k["bank"], k["pitch"], k["yaw"])
    sol = g.solve_pose(hz, left, right, F, D)
    np.testing.assert_allclose(sol.bank, k["bank"], atol=1e-9)
    np.testing.assert_allclose(sol.pitch, k["pitch"], atol=1e-9)
    np.testing.assert_allclose(sol.yaw, k["yaw"], atol=1e-9)
    np.testing.assert_allclose(sol.height_m, k["h"], rtol=1e-9)
    np.testing.assert_allclose(sol.lateral_m, k["y"], atol=1e-9)
    np.testing.assert_allclose(sol.misclosure_px, 0.0, atol=1e-6)
    # the edges are told apart by geometry, not by argument order
    swapped = g.solve_pose(hz, right, left, F, D)
    np.testing.assert_allclose(swapped.lateral_m, k["y"], atol=1e-9)
    np.testing.assert_allclose(swapped.right_edge, sol.right_edge, atol=1e-12)
    # independently built edges (two ground points each) give the same answer
    r2, l2 = _edge_lines_by_points(k["bank"], k["pitch"], k["yaw"], k["y"], k["h"])
    sol2 = g.solve_pose(hz, r2, l2, F, D)
    np.testing.assert_allclose(sol2.height_m, k["h"], rtol=1e-9)
    np.testing.assert_allclose(sol2.lateral_m, k["y"], atol=1e-9)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(
    bank=st.floats(-20, 20),
    pitch=st.floats(-10, 5),
    yaw=st.floats(-10, 10),
    h=st.floats(5, 500),
    lat=st.floats(-40, 40),
    off=st.tuples(st.floats(-10, 10), st.floats(-3, 3), st.floats(-3, 3)),
    d=st.floats(10, 40),
    f=st.floats(300, 3000),
)
def test_solve_pose_round_trip_with_mounting_offset(bank, pitch, yaw, h, lat, off, d, f):
    b, p, y = math.radians(bank), math.radians(pitch), math.radians(yaw)
    rot = g.rotation_matrix(b, p, y)
    ref = np.array([0.0, lat, -h])
    cam = ref + rot.T @ np.array(off)  # camera position in the earth frame
    right, left = g.runway_edge_lines(b, p, y, cam[1], -cam[2], d, f)
    hz = _horizon_from_projection(np.float64(b), np.float64(p), np.float64(y), f)
    sol = g.solve_pose(hz, right, left, f, d, camera_offset_m=off)
    assert float(sol.bank) == pytest.approx(b, abs=1e-9)
    assert float(sol.pitch) == pytest.approx(p, abs=1e-9)
    assert float(sol.yaw) == pytest.approx(y, abs=1e-9)
    assert float(sol.height_m) == pytest.approx(h, rel=1e-9)
    assert float(sol.lateral_m) == pytest.approx(lat, abs=1e-9)
    assert float(sol.camera_height_m) == pytest.approx(-cam[2], rel=1e-9)


def test_fit_concurrent_lines_recovers_exact_lines_and_their_common_point():
    vp = np.array([12.0, -30.0])
    sets, truth = [], []
    for ang, s_range in ((0.2, (-300, 300)), (1.3, (40, 260)), (1.9, (30, 250))):
        t = np.array([math.cos(ang), math.sin(ang)])
        s = np.linspace(*s_range, 25)
        sets.append((vp[0] + s * t[0], vp[1] + s * t[1]))
        truth.append(g.line_through(tuple(vp), tuple(vp + t)))
    vx, vy, lines = g.fit_concurrent_lines(sets)
    assert (vx, vy) == pytest.approx(tuple(vp), abs=1e-9)
    for ln, tr in zip(lines, truth, strict=True):
        assert abs(float(np.dot(ln[:2], tr[:2]))) == pytest.approx(1.0, abs=1e-12)
        assert float(g.point_line_distance(ln, *vp)) == pytest.approx(0.0, abs=1e-9)


def test_fit_concurrent_lines_beats_independent_fits_on_noisy_edges():
    rng = np.random.default_rng(7)
    bank, pitch, yaw, h, lat = map(np.float64,
                                   (math.radians(8), math.radians(-3), math.radians(4), 400.0, 12.0))
    right, left = g.runway_edge_lines(bank, pitch, yaw, lat, h, D, F)
    hz = g.horizon_line(bank, pitch, F)
    vx, vy = g.vanishing_point(bank, pitch, yaw, F)
    err_free, err_conc = [], []
    for _ in range(200):
        sets = []
        for line, (s0, s1) in ((hz, (-300, 300)), (right, (80, 240)), (left, (80, 240))):
            t = np.array([-line[1], line[0]])
            t = t if t[1] < 0 or line is hz else -t  # edges: from the vanishing point downwards
            s = np.linspace(s0, s1, 40)
            x, y = vx + s * t[0], vy + s * t[1]
            sets.append((x + rng.normal(0, 0.15, 40) * line[0], y + rng.normal(0, 0.15, 40) * line[1]))
        free = [g.fit_line(*s) for s in sets]
        _, _, conc = g.fit_concurrent_lines(sets)
        err_free.append(float(g.solve_pose(*free, F, D).height_m) / h - 1)
        err_conc.append(float(g.solve_pose(*conc, F, D).height_m) / h - 1)
    assert np.sqrt(np.mean(np.square(err_conc))) < 0.5 * np.sqrt(np.mean(np.square(err_free)))
    assert abs(np.mean(err_conc)) < 0.005


def test_projection_matches_opencv_project_points():
    """Eq. (1)-(2) against cv2.projectPoints: earth → camera built from three cv2.Rodrigues
    frame rotations (yaw about z, pitch about y, bank about x), the spec's camera axes
    (X forward, Y right, Z down) permuted to OpenCV's (right, down, forward); pixel
    u = x' + c_x, v = -y' + c_y."""
    import cv2

    rng = np.random.default_rng(8)
    rod = lambda v: cv2.Rodrigues(np.array(v, dtype=float))[0]  # noqa: E731
    to_cv = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    cx, cy = 319.5, 239.5
    k = np.array([[F, 0.0, cx], [0.0, F, cy], [0.0, 0.0, 1.0]])
    for _ in range(20):
        bank, pitch, yaw = np.radians(rng.uniform([-20, -10, -10], [20, 5, 10]))
        cam = np.array([rng.uniform(-3000, -200), rng.uniform(-40, 40), -rng.uniform(5, 500)])
        pts = np.column_stack([rng.uniform(0, 3000, 30), rng.uniform(-D, D, 30), np.zeros(30)])
        r_cv = to_cv @ rod([-bank, 0, 0]) @ rod([0, -pitch, 0]) @ rod([0, 0, -yaw])
        uv, _ = cv2.projectPoints(pts, cv2.Rodrigues(r_cv)[0], -r_cv @ cam, k, None)
        x, y, depth = g.project_points(pts, cam, bank, pitch, yaw, F)
        front = depth > 0
        assert front.sum() >= 10
        np.testing.assert_allclose(x[front] + cx, uv[front, 0, 0], atol=1e-8)
        np.testing.assert_allclose(-y[front] + cy, uv[front, 0, 1], atol=1e-8)
