"""Path deviation (radar-interface.md §6) against hand-made cases and an independent brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import ROOT

from radar_io.coordinates.reference_path import PathError, ReferencePath, add_deviation, load_path
from radar_io.coordinates.transforms import load_site
from radar_io.decoding.decoders import decode_bytes
from radar_io.errors import ConfigError, RadarIOError
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

TOL = 1e-6


# ------------------------------------------------------------------ signs on hand-made cases
def test_signs_straight_leg_radar_frame():
    north = ReferencePath([[0, 0, 100], [10000, 0, 100]], 500)     # flying north
    d = north.deviation([5000, 5000, 5000], [50, -50, 0], [100, 100, 130])
    # east of a northbound aircraft is on its right; above is positive
    assert d["dy_m"].tolist() == [50, -50, 0]
    assert d["dz_m"].tolist() == [0, 0, 30]
    assert d["along_m"].tolist() == [5000, 5000, 5000]
    south = ReferencePath([[10000, 0, 100], [0, 0, 100]], 500)     # flying south: east is left
    assert south.deviation(5000, 50, 90)["dy_m"] == -50
    assert south.deviation(5000, 50, 90)["dz_m"] == -10
    east = ReferencePath([[0, 0, 0], [0, 10000, 0]], 500)          # flying east: south is right
    assert east.deviation(-20, 3000, 0)["dy_m"] == 20


def test_signs_runway_frame():
    # runway frame: X_r along the approach, Y_r to the right, H_r up
    final = ReferencePath([[-10000, 0, 539], [0, 0, 15]], 1000, frame="runway")
    d = final.deviation([-5000, -5000], [30, -30], [300, 250])
    assert d["dy_m"].tolist() == [30, -30]
    assert d["dz_m"] == pytest.approx([300 - 277, 250 - 277], abs=TOL)


# ------------------------------------------------------------------ exact arcs, built by hand
R = 2000.0


def right_turn():
    """North 10 km, then east: a RIGHT turn (clockwise seen from above) filleted with R."""
    return ReferencePath([[0, 0, 100], [10000, 0, 300], [10000, 10000, 500]], R)


def left_turn():
    """North 10 km, then west: a LEFT turn."""
    return ReferencePath([[0, 0, 100], [10000, 0, 300], [10000, -10000, 500]], R)


def hand_height(s):
    # stations: 0, the arc's middle (8000 + R*pi/4), the end (8000 + R*pi/2 + 8000)
    st = [0.0, 8000 + R * math.pi / 4, 16000 + R * math.pi / 2]
    return np.interp(s, st, [100, 300, 500])


@pytest.mark.parametrize("turn", ["right", "left"])
def test_arc_offsets_come_back_exactly(turn):
    path = right_turn() if turn == "right" else left_turn()
    sgn = 1.0 if turn == "right" else -1.0
    cx, cy = 8000.0, sgn * 2000.0                  # tangent points (8000, 0) and (10000, ±2000)
    phi = np.linspace(0.0, math.pi / 2, 37)
    rng = np.random.default_rng(5)
    for dy in (-400.0, -37.5, 0.0, 12.25, 400.0):
        foot_x = cx + R * np.sin(phi)
        foot_y = cy - sgn * R * np.cos(phi)
        # right-hand normal of the direction of flight (u_x, u_y) is (-u_y, u_x)
        ux, uy = np.cos(phi), sgn * np.sin(phi)
        dz = rng.uniform(-80, 80, phi.size)
        s = 8000 + R * phi
        x, y = foot_x - dy * uy, foot_y + dy * ux
        d = path.deviation(x, y, hand_height(s) + dz)
        assert np.max(np.abs(d["dy_m"] - dy)) <= TOL
        assert np.max(np.abs(d["along_m"] - s)) <= TOL
        assert np.max(np.abs(d["dz_m"] - dz)) <= TOL
        assert (d["leg"][1:-1] == 1).all()       # (the tangent points belong to the straights)
    # the inside of a right turn (towards the centre) is to the right
    d = path.deviation(cx + 1000 * math.sin(0.5), cy - sgn * 1000 * math.cos(0.5), 0)
    assert d["dy_m"] == pytest.approx(sgn * 1000, abs=TOL)


@pytest.mark.parametrize("turn", ["right", "left"])
def test_straight_legs_of_a_turning_path(turn):
    path = right_turn() if turn == "right" else left_turn()
    sgn = 1.0 if turn == "right" else -1.0
    # first leg (flying north): along = x
    d = path.deviation([3000, 3000], [120, -120], [0, 0])
    assert d["dy_m"].tolist() == [120, -120]
    assert d["along_m"].tolist() == [3000, 3000]
    assert (d["leg"] == 0).all()
    assert d["dz_m"] == pytest.approx(-hand_height(3000.0), abs=TOL)
    # last leg, flying east after the right turn (north of it is left) and west after the
    # left turn (north of it is right)
    y = sgn * 6000.0
    d = path.deviation([10000 + 75, 10000 - 75], [y, y], [400, 400])
    assert d["dy_m"] == pytest.approx([-sgn * 75, sgn * 75], abs=TOL)
    s = 8000 + R * math.pi / 2 + 4000
    assert d["along_m"] == pytest.approx([s, s], abs=TOL)
    assert d["dz_m"] == pytest.approx(400 - hand_height(s), abs=TOL)
    assert (d["leg"] == 2).all()


def test_before_first_and_after_last_extend_the_end_legs():
    path = right_turn()
    slope0 = (300 - 100) / (8000 + R * math.pi / 4)
    d = path.deviation([-1000, -5000], [-40, 25], [0, 0])
    assert d["along_m"].tolist() == [-1000, -5000]
    assert d["dy_m"].tolist() == [-40, 25]
    assert (d["leg"] == 0).all()
    assert d["dz_m"] == pytest.approx([-(100 - 1000 * slope0), -(100 - 5000 * slope0)], abs=TOL)
    end = 16000 + R * math.pi / 2
    slope1 = (500 - 300) / (end - (8000 + R * math.pi / 4))
    d = path.deviation([10030, 9990], [13000, 11000], [600, 600])   # flying east: north is left
    assert d["along_m"] == pytest.approx([end + 3000, end + 1000], abs=TOL)
    assert d["dy_m"] == pytest.approx([-30, 10], abs=TOL)
    assert (d["leg"] == 2).all()
    assert d["dz_m"] == pytest.approx([600 - (500 + 3000 * slope1), 600 - (500 + 1000 * slope1)],
                                      abs=TOL)
    assert path.length_m == pytest.approx(end, abs=TOL)


def test_nan_in_nan_out_and_shapes():
    path = right_turn()
    x = np.array([[1000.0, np.nan], [5000.0, 7000.0]])
    y = np.array([[0.0, 0.0], [np.nan, 10.0]])
    h = np.array([[100.0, 100.0], [100.0, np.nan]])
    d = path.deviation(x, y, h)
    assert d["dy_m"].shape == (2, 2)
    assert np.isnan(d["dy_m"][0, 1]) and np.isnan(d["dy_m"][1, 0])
    assert d["leg"][0, 1] == -1 and d["leg"][1, 0] == -1
    assert np.isfinite(d["dy_m"][1, 1]) and np.isnan(d["dz_m"][1, 1])
    assert np.isnan(d["along_m"][0, 1])


# ------------------------------------------------------------------ brute force on random paths
def brute_force(points, radius, px, py):
    """Nearest point on the filleted path by dense sampling + golden-section refinement.

    The fillet geometry is rebuilt here from first principles: the tangent
    points lie radius*tan(turn/2) from the corner along each leg; the arc
    centre is radius from the first tangent point along the leg's normal
    towards the turn. Returns (signed dy, along) with dy > 0 right of the path.
    """
    p = np.asarray(points, float)[:, :2]
    pieces = []              # callables s -> (x, y, tx, ty), with their length
    s = 0.0
    tan_len = [0.0]
    for i in range(1, len(p) - 1):
        a, b = p[i] - p[i - 1], p[i + 1] - p[i]
        a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
        ang = math.acos(max(-1.0, min(1.0, float(a @ b))))
        tan_len.append(radius * math.tan(ang / 2))
    tan_len.append(0.0)
    for i in range(len(p) - 1):
        u = (p[i + 1] - p[i]) / np.linalg.norm(p[i + 1] - p[i])
        start = p[i] + tan_len[i] * u
        length = np.linalg.norm(p[i + 1] - p[i]) - tan_len[i] - tan_len[i + 1]
        first, last = i == 0, i == len(p) - 2
        pieces.append(("line", start, u, length, s, first, last))
        s += length
        if i + 1 < len(p) - 1:
            v = (p[i + 2] - p[i + 1]) / np.linalg.norm(p[i + 2] - p[i + 1])
            cross = u[0] * v[1] - u[1] * v[0]
            ang = math.acos(max(-1.0, min(1.0, float(u @ v))))
            side = 1.0 if cross > 0 else -1.0      # + : turning from X towards Y = right
            a0 = p[i + 1] - tan_len[i + 1] * u
            normal = np.array([-u[1], u[0]]) * side
            centre = a0 + radius * normal
            pieces.append(("arc", centre, a0 - centre, ang, s, side))
            s += radius * ang
    best = (math.inf, 0.0, 0.0)
    q = np.array([px, py])
    for pc in pieces:
        if pc[0] == "line":
            _, start, u, length, s0, first, last = pc
            lo, hi = (-1e6 if first else 0.0), (length + 1e6 if last else length)

            def pos(t, start=start, u=u):
                return start + np.multiply.outer(t, u)
        else:
            _, centre, r0, ang, s0, side = pc
            lo, hi = 0.0, radius * ang

            def pos(t, centre=centre, r0=r0, side=side):
                c, sn = np.cos(side * np.asarray(t) / radius), np.sin(side * np.asarray(t) / radius)
                return centre + np.stack([r0[0] * c - r0[1] * sn, r0[0] * sn + r0[1] * c], axis=-1)

        def f(t, pos=pos):
            return np.linalg.norm(pos(t) - q, axis=-1)

        ts = np.linspace(lo, hi, 4001)
        k = int(np.argmin(f(ts)))
        a, b = ts[max(k - 1, 0)], ts[min(k + 1, ts.size - 1)]
        g = (math.sqrt(5) - 1) / 2
        for _ in range(100):
            c, d = b - g * (b - a), a + g * (b - a)
            if f(c) < f(d):
                b = d
            else:
                a = c
        t = (a + b) / 2
        if f(t) < best[0]:
            e = q - pos(t)
            tangent = pos(t + 1e-3) - pos(t - 1e-3)
            side_sign = math.copysign(1.0, tangent[0] * e[1] - tangent[1] * e[0])  # + : right
            best = (float(f(t)), s0 + t, side_sign)
    return best[2] * best[0], best[1]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_paths_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    # a zig-zag course with turns of 20..120 degrees both ways
    heading, pos, pts = rng.uniform(0, 2 * math.pi), np.zeros(2), []
    for _ in range(5):
        pts.append([pos[0], pos[1], rng.uniform(200, 1500)])
        heading += rng.choice([-1, 1]) * math.radians(rng.uniform(20, 120))
        pos = pos + rng.uniform(6000, 9000) * np.array([math.cos(heading), math.sin(heading)])
    path = ReferencePath(pts, 1200.0)
    # samples near the path: points of the path offset by up to ±500 m
    s = rng.uniform(-1000, path.length_m + 1000, 40)
    x0, y0, _ = path.position(s)
    x = x0 + rng.uniform(-500, 500, s.size)
    y = y0 + rng.uniform(-500, 500, s.size)
    d = path.deviation(x, y, np.zeros(s.size))
    for i in range(s.size):
        dy, along = brute_force(pts, 1200.0, x[i], y[i])
        assert d["dy_m"][i] == pytest.approx(dy, abs=TOL)
        assert d["along_m"][i] == pytest.approx(along, abs=1e-4)


# ------------------------------------------------------------------ path files
def write(tmp_path, text):
    f = tmp_path / "p.toml"
    f.write_text(text)
    return f


PTS = "[[points]]\nx_m = 0.0\ny_m = 0.0\nh_m = 100.0\n"


@pytest.mark.parametrize("text, message", [
    ('frame = "radar"\nturn_radius_m = 1000.0\n' + PTS, "field points: expected at least 2 entries, got 1"),
    ('frame = "radar"\nturn_radius_m = 1000.0\n' + PTS + PTS, "same horizontal position"),
    ('frame = "radar"\nturn_radius_m = 5000.0\n' + PTS +
     "[[points]]\nx_m = 3000.0\ny_m = 0.0\nh_m = 1.0\n[[points]]\nx_m = 3000.0\ny_m = 3000.0\nh_m = 1.0\n",
     "too large for the corner"),
    ('frame = "radar"\nturn_radius_m = 100.0\n' + PTS +
     "[[points]]\nx_m = 3000.0\ny_m = 0.0\nh_m = 1.0\n[[points]]\nx_m = 1000.0\ny_m = 0.0\nh_m = 1.0\n",
     "reverses direction"),
    ('frame = "radar"\nturn_radius_m = 1000.0\n[[points]]\nx_m = "north"\ny_m = 0.0\nh_m = 1.0\n' + PTS,
     "field points[0].x_m: expected a number, got a string 'north'"),
    ('frame = "radar"\nturn_radius_m = -5.0\n' + PTS + PTS, "field turn_radius_m: -5.0 is out of range"),
    ('frame = "radar"\nturn_radius_m = 1000.0\n[[points]]\nx_m = 1.0\ny_m = 0.0\nz_m = 1.0\n' + PTS,
     "field points[0].z_m: unknown key"),
    ('frame = "geodetic"\nturn_radius_m = 1000.0\n' + PTS + PTS, "field frame: expected 'radar' or 'runway'"),
    ('turn_radius_m = 1000.0\n' + PTS + PTS, "field frame: missing"),
    ('frame = "radar"\n' + PTS + PTS, "field turn_radius_m: missing"),
    ('frame = "radar"\nturn_radius_m = 1000.0\npoints = 3\n', "field points: expected an array of tables"),
    ("frame = = 1\n", "is not valid TOML"),
])
def test_bad_path_files(tmp_path, text, message):
    f = write(tmp_path, text)
    with pytest.raises(PathError) as exc:
        load_path(f)
    assert message in str(exc.value)
    assert isinstance(exc.value, ConfigError) and isinstance(exc.value, RadarIOError)
    assert "\n" not in str(exc.value)


def test_missing_path_file(tmp_path):
    with pytest.raises(PathError, match="not found"):
        load_path(tmp_path / "nope.toml")


def test_radius_exactly_fits_is_accepted():
    # north, east, south: two right-hand 90-degree corners on a 2000 m leg need exactly
    # 2 * 1000 m, leaving a zero-length straight; the two arcs form a semicircle about (4000, 1000)
    p = ReferencePath([[0, 0, 0], [5000, 0, 0], [5000, 2000, 0], [0, 2000, 0]], 1000.0)
    assert [e.kind for e in p.elements] == ["line", "arc", "line", "arc", "line"]
    assert p.elements[2].length == pytest.approx(0.0, abs=1e-9)
    d = p.deviation([4300, 5200, 4000 + 1200 * math.cos(1.2)], [1000, 1000, 1000 + 1200 * math.sin(1.2)],
                    [0, 0, 0])
    assert d["dy_m"] == pytest.approx([700, -200, -200], abs=TOL)    # the centre side is right
    assert d["along_m"] == pytest.approx([4000 + 500 * math.pi, 4000 + 500 * math.pi,
                                          4000 + 1000 * (1.2 + math.pi / 2)], abs=TOL)
    assert d["leg"].tolist() == [1, 1, 3]


def test_example_paths_load():
    for f in sorted((ROOT / "firmware_specs" / "paths").glob("*.toml")):
        p = load_path(f)
        assert p.length_m > 0 and p.frame in ("radar", "runway")


# ------------------------------------------------------------------ on decoded batches
def test_add_deviation_on_a_simulated_flight():
    script = FlightScript()
    sim = RadarSimulator(script, SimConfig(tod_start_s=1000.0, seed=4, ng_per_min=30))
    data, truth = sim.generate(4000)
    site = load_site(ROOT / "firmware_specs" / "sites" / "demo.toml")
    batch = decode_bytes(data, site=site)
    end = script.position(np.array([script.duration_s]))
    radar = ReferencePath([[script.start_x_m, script.start_y_m, script.height_m],
                           [end[0][0], end[1][0], script.height_m]], 1000.0)
    out = add_deviation(batch, radar)
    assert out.columns[-4:] == ("dy_m", "dz_m", "along_m", "leg")
    assert out.stats == batch.stats and len(out) == len(batch)
    ng = batch["rx_good"] == 0
    assert ng.any() and np.isnan(out["dy_m"][ng]).all() and (out["leg"][ng] == -1).all()
    good = ~ng
    # the simulated flight is the path: deviations are the radar noise (angles 0.005 deg at ~15 km)
    assert np.abs(out["dy_m"][good]).max() < 10 and np.abs(out["dz_m"][good]).max() < 10
    # the flight starts at the first pass point at 70 m/s
    assert np.allclose(out["along_m"][good], 70.0 * truth["t_s"][good], atol=10)
    # the same path in the runway frame gives the same deviations
    pts = radar.points
    rel = np.radians(0 - site.runway_heading_deg)
    xr = pts[:, 0] * math.cos(rel) - pts[:, 1] * math.sin(rel) + site.radar_xr_m
    yr = pts[:, 0] * math.sin(rel) + pts[:, 1] * math.cos(rel) + site.radar_yr_m
    runway = ReferencePath(np.c_[xr, yr, pts[:, 2] + site.radar_hr_m], 1000.0, frame="runway")
    out_r = add_deviation(batch, runway)
    assert np.allclose(out_r["dy_m"][good], out["dy_m"][good], atol=1e-6)
    assert np.allclose(out_r["dz_m"][good], out["dz_m"][good], atol=1e-6)
    with pytest.raises(PathError, match="--site"):
        add_deviation(decode_bytes(data), runway)
