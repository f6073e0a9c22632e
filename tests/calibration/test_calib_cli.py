"""``radar-io calibrate …`` end to end, as a separate process."""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyproj
import pytest

from radar_io.calibration import Pose
from radar_io.decoding.biases import load_calibration

from .synthetic import FOCAL_MM, aerial_photo


def run(*args: str) -> subprocess.CompletedProcess:
    """``radar-io calibrate …`` in a fresh interpreter (the installed console script's entry point)."""
    return subprocess.run([sys.executable, "-m", "radar_io.cli", "calibrate", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def ok_json(*args: str) -> dict:
    p = run(*args)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def bad(*args: str, match: str) -> str:
    p = run(*args)
    assert p.returncode != 0
    assert "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    assert match in lines[0], lines[0]
    assert p.stdout == ""
    return lines[0]


def write_csv(path: Path, header: str, rows) -> Path:
    path.write_text(header + "\n" + "\n".join(",".join(f"{v}" for v in r) for r in rows) + "\n")
    return path


@pytest.mark.slow
def test_resection(tmp_path):
    rng = np.random.default_rng(1)
    truth = Pose(6200.0, 2800.0, -900.0, 1.2, -2.1, 37.0)
    _, pts, film = aerial_photo(rng, n=12, pose=truth)
    film = film + rng.normal(scale=0.05, size=film.shape)
    csv = write_csv(tmp_path / "photo.csv", "x_m,y_m,z_m,px_mm,py_mm", np.column_stack([pts, film]).round(6))
    out = ok_json("resection", csv, "--focal-mm", FOCAL_MM, "--monte-carlo", 20, "--seed", 3)
    keys = {"x0_m", "y0_m", "z0_m", "phi_deg", "theta_deg", "psi_deg"}
    assert keys | {"iterations", "rms_mm", "sigma", "monte_carlo"} <= set(out)
    assert set(out["sigma"]) == keys and set(out["monte_carlo"]) == keys
    assert abs(out["x0_m"] - 6200) < 15 and abs(out["z0_m"] + 900) < 5 and abs(out["psi_deg"] - 37) < 0.5
    assert 0.02 < out["rms_mm"] < 0.1 and out["iterations"] <= 8
    assert 0.1 < out["monte_carlo"]["x0_m"] < 20 and out["monte_carlo_info"]["seed"] == 3
    # the same seed gives the same numbers; a start and the refraction switch are accepted
    again = ok_json("resection", csv, "--focal-mm", FOCAL_MM, "--monte-carlo", 20, "--seed", 3)
    assert again["monte_carlo"] == out["monte_carlo"]
    refr = ok_json("resection", csv, "--focal-mm", FOCAL_MM, "--start=6000,3000,-1000,0,0,40",
                   "--refraction", "--aircraft-height-m", 900)
    assert 0.3 < out["z0_m"] - refr["z0_m"] < 3.0  # the correction raises the camera


@pytest.mark.slow
def test_resection_bad_input(tmp_path):
    bad("resection", tmp_path / "missing.csv", "--focal-mm", 40, match="not found")
    csv = write_csv(tmp_path / "p.csv", "x_m,y_m,z_m,px_mm", [[1, 2, 3, 4]] * 4)
    bad("resection", csv, "--focal-mm", 40, match="missing column(s) py_mm")
    csv = write_csv(tmp_path / "q.csv", "x_m,y_m,z_m,px_mm,py_mm", [[1, 2, 3, 4, 5], [1, 2, "abc", 4, 5]])
    bad("resection", csv, "--focal-mm", 40, match="line 3, column z_m")
    csv = write_csv(tmp_path / "r.csv", "x_m,y_m,z_m,px_mm,py_mm", [[0, 0, 0, 1, 1], [10, 10, 0, 2, 2]])
    bad("resection", csv, "--focal-mm", 40, match="at least 3 control points")
    bad("resection", csv, "--focal-mm", "-4", match="--focal-mm")
    bad("resection", csv, "--focal-mm", 40, "--refraction", match="--aircraft-height-m")


PAIRS = [
    # group, radar_sr_m, radar_el_deg, radar_az_deg, photo_x_m, photo_y_m, photo_z_m
    ("F1", 4995.0, 0.02, 53.10, 3000.0, 4000.0, 0.0),
    ("F1", 2824.0, 44.97, 359.98, 2000.0, 0.0, -2000.0),
    ("F2", 4997.0, -0.01, 53.14, 3000.0, 4000.0, 0.0),
]


def test_bias_writes_a_calibration_set(tmp_path):
    csv = write_csv(tmp_path / "pairs.csv",
                    "group,radar_sr_m,radar_el_deg,radar_az_deg,photo_x_m,photo_y_m,photo_z_m", PAIRS)
    cal_path = tmp_path / "cal.json"
    out = ok_json("bias", csv, "-o", cal_path)
    az0 = math.degrees(math.atan2(4000, 3000))
    f1_dsr = [5000 - 4995, 2000 * math.sqrt(2) - 2824]
    f1_daz = [az0 - 53.10, 0.02]  # 0 − 359.98 wraps to +0.02
    f1, f2, comb = out["groups"]["F1"], out["groups"]["F2"], out["combined"]
    assert f1["n"] == 2 and f2["n"] == 1 and comb["n"] == 3
    assert f1["dsr_m"]["mean"] == pytest.approx(sum(f1_dsr) / 2)
    assert f1["dsr_m"]["std"] == pytest.approx(abs(f1_dsr[0] - f1_dsr[1]) / 2)
    assert f1["daz_deg"]["mean"] == pytest.approx(sum(f1_daz) / 2)
    assert f1["del_deg"]["mean"] == pytest.approx(((0 - 0.02) + (45 - 44.97)) / 2)
    assert f2["dsr_m"] == {"mean": pytest.approx(3.0), "std": 0.0}
    assert comb["dsr_m"]["mean"] == pytest.approx((sum(f1_dsr) / 2 + 3.0) / 2)
    assert comb["daz_deg"]["std"] == pytest.approx((abs(f1_daz[0] - f1_daz[1]) / 2 + 0.0) / 2)
    cal = load_calibration(cal_path)
    assert cal.dsr_m == pytest.approx(comb["dsr_m"]["mean"])
    assert cal.del_deg == pytest.approx(comb["del_deg"]["mean"])
    assert cal.daz_deg == pytest.approx(comb["daz_deg"]["mean"])
    assert cal.provenance["input"] == "pairs.csv"
    assert cal.provenance["input_sha256"] == hashlib.sha256(csv.read_bytes()).hexdigest()
    assert cal.provenance["pairs"] == 3 and cal.provenance["groups"] == 2
    assert cal.statistics == out and cal.created_utc.endswith("Z")


def test_bias_bad_input(tmp_path):
    csv = write_csv(tmp_path / "a.csv", "group,radar_sr_m,radar_el_deg,radar_az_deg", [("F1", 1, 2, 3)])
    bad("bias", csv, match="either photo_x_m")
    csv = write_csv(tmp_path / "b.csv",
                    "group,radar_sr_m,radar_el_deg,radar_az_deg,photo_sr_m,photo_el_deg,photo_az_deg",
                    [("F1", 1, 2, 3, 1, 2, 3), ("F1", 1, "", 3, 1, 2, 3)])
    bad("bias", csv, match="line 3, column radar_el_deg")


@pytest.mark.slow
def test_camera(tmp_path):
    theta = [0.0, -20.0, -10.0, 10.0, 20.0, 25.0]
    rows = []
    for axis, dt, f, pc in (("x", 0.37, 40.2, 0.12), ("y", -0.21, 40.3, -0.05)):
        rows += [(axis, t, pc + f * math.tan(math.radians(t - dt))) for t in theta]
    csv = write_csv(tmp_path / "targets.csv", "axis,theta_deg,film_mm", rows)
    out = ok_json("camera", csv)
    x, y = out["axes"]["x"], out["axes"]["y"]
    assert x["delta_theta_deg"] == pytest.approx(0.37) and y["delta_theta_deg"] == pytest.approx(-0.21)
    assert x["focal_mm"] == pytest.approx(40.2) and y["focal_mm"] == pytest.approx(40.3)
    assert x["principal_point_mm"] == pytest.approx(0.12) and y["principal_point_mm"] == pytest.approx(-0.05)
    assert out["focal_nominal_mm"] == pytest.approx(40.25)
    assert x["distortion"]["a1"] == pytest.approx(40.25 / 40.2)
    bad("camera", write_csv(tmp_path / "c.csv", "axis,theta_deg,film_mm", [*rows[:5], ("z", 1, 1)]),
        match="line 7, column axis")
    bad("camera", write_csv(tmp_path / "d.csv", "axis,theta,film_mm", rows),
        match="missing column(s) theta_deg")


@pytest.mark.slow
def test_mapgrid(tmp_path):
    crs = pyproj.CRS.from_epsg(30169)
    fwd = pyproj.Transformer.from_crs(crs.geodetic_crs, crs, always_xy=True)
    se, sn = fwd.transform(139.95, 35.75)
    rows = [(f"P{i}", sn + 1000 * i, se + 700 * (i % 3) - 500 * (i % 2), 10.0 + i) for i in range(8)]
    csv = write_csv(tmp_path / "gcp.csv", "name,map_x_m,map_y_m,map_h_m", rows)
    out = ok_json("mapgrid", csv, "--zone", 9, "--datum", "tokyo", f"--site={sn},{se},20")
    assert out["crs"] == "EPSG:30169"
    assert out["site"]["lat_deg"] == pytest.approx(35.75) and out["site"]["lon_deg"] == pytest.approx(139.95)
    assert [p["name"] for p in out["points"]] == [r[0] for r in rows]
    p7 = out["points"][7]
    # 7 km north, up to 1.4 km east: close to the map differences, curvature drop in z
    assert abs(p7["x_m"] - 7000) < 10 and abs(p7["z_m"] - (-(17.0 - 20.0))) < 6
    assert set(out["model"]) == {"x", "y", "h"} and out["model"]["h"]["max_abs_m"] < 0.01
    same = ok_json("mapgrid", csv, "--crs", "EPSG:30169", f"--site={sn},{se},20")
    assert same["points"] == out["points"]
    bad("mapgrid", csv, "--crs", "EPSG:4326", f"--site={sn},{se},20", match="not a projected")
    bad("mapgrid", csv, f"--site={sn},{se},20", match="either --crs or --zone")
    bad("mapgrid", write_csv(tmp_path / "e.csv", "map_x_m,map_y_m,map_h_m", [(1, "1e", 3)]), "--zone", 9,
        "--site=0,0,0", match="line 2, column map_y_m")
