"""Manual mode: the pose from operator-picked points (two or more per line, ±0.5 px)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from radar_io.vision import VisionError
from radar_io.vision import pose_equations as g
from radar_io.vision.manual import load_points, pose_from_points
from radar_io.vision.synth import RunwayPose, focal_for_fov

D = 22.5


def _picked_points(pose: RunwayPose, width: int, height: int, f: float, n: int, rng) -> dict[str, np.ndarray]:
    """n points per line, spread along what is visible in the frame, with uniform ±0.5 px picking error."""
    pp = ((width - 1) / 2.0, (height - 1) / 2.0)
    bank, pitch, yaw = pose.angles_rad
    cam = pose.camera_position()
    hz = []
    for a in np.linspace(-0.45, 0.45, n):  # horizon: images of horizontal directions
        d = np.array([math.cos(yaw + a), math.sin(yaw + a), 0.0])
        x, y, _ = g.project_points(d, np.zeros(3), bank, pitch, yaw, f)
        hz.append(g.image_to_pixel(x, y, pp))
    pts = {"horizon": np.array(hz, float)}
    for key, side in (("right_edge", D), ("left_edge", -D)):
        xs = np.linspace(cam[0] - 300.0, cam[0] + 4000.0, 6000)
        ground = np.stack([xs, np.full_like(xs, side), np.zeros_like(xs)], -1)
        x, y, depth = g.project_points(ground, cam, bank, pitch, yaw, f)
        uv = np.stack(g.image_to_pixel(x, y, pp), -1)
        ok = ((depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1)
              & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1))
        uv = uv[ok]
        arc = np.r_[0.0, np.cumsum(np.hypot(*np.diff(uv, axis=0).T))]
        idx = np.searchsorted(arc, np.linspace(0.0, arc[-1], n)).clip(0, len(uv) - 1)
        pts[key] = uv[idx]
    return {k: v + rng.uniform(-0.5, 0.5, v.shape) for k, v in pts.items()}


@pytest.mark.parametrize("size, max_height", [((640, 480), 300.0), ((1280, 720), 500.0)])
def test_manual_mode_recovers_the_pose(size, max_height):
    w, h = size
    f = focal_for_fov(w)
    pp = ((w - 1) / 2.0, (h - 1) / 2.0)
    rng = np.random.default_rng(3)
    for _ in range(60):
        pose = RunwayPose(
            rng.uniform(-20, 20),
            rng.uniform(-10, 5),
            rng.uniform(-10, 10),
            float(np.exp(rng.uniform(math.log(5), math.log(max_height)))),
            rng.uniform(-40, 40),
        )
        res = pose_from_points(_picked_points(pose, w, h, f, 3, rng), f, D, pp)
        assert res.found, (pose, res.reason)
        assert abs(res.bank_deg - pose.bank_deg) <= 0.3
        assert abs(res.pitch_deg - pose.pitch_deg) <= 0.3
        assert abs(res.yaw_deg - pose.yaw_deg) <= 0.3
        assert res.height_m == pytest.approx(pose.height_m, rel=0.03)
        assert abs(res.lateral_m - pose.lateral_m) <= 0.05 * pose.height_m + 0.5


class _NoNoise:
    """Stands in for the random generator: no picking error."""

    @staticmethod
    def uniform(lo, hi, shape):
        return np.zeros(shape)


def test_exact_points_give_the_exact_pose_and_labels_do_not_matter():
    f = focal_for_fov(640)
    pose = RunwayPose(12.0, -6.0, 4.0, 35.0, -14.0, (3.0, 0.0, -1.0))
    exact = _picked_points(pose, 640, 480, f, 4, _NoNoise())
    rounded = {k: v.round(0) for k, v in _picked_points(pose, 640, 480, f, 2, _NoNoise()).items()}
    res = pose_from_points(exact, f, D, (319.5, 239.5), camera_offset_m=pose.camera_offset_m)
    assert res.found and res.quality == pytest.approx(1.0, abs=1e-9)
    assert res.bank_deg == pytest.approx(pose.bank_deg, abs=1e-7)
    assert res.pitch_deg == pytest.approx(pose.pitch_deg, abs=1e-7)
    assert res.yaw_deg == pytest.approx(pose.yaw_deg, abs=1e-7)
    assert res.height_m == pytest.approx(pose.height_m, rel=1e-9)
    assert res.lateral_m == pytest.approx(pose.lateral_m, abs=1e-7)
    swapped = dict(exact, left_edge=exact["right_edge"], right_edge=exact["left_edge"])
    res2 = pose_from_points(swapped, f, D, (319.5, 239.5), camera_offset_m=pose.camera_offset_m)
    assert res2.lateral_m == pytest.approx(res.lateral_m, abs=1e-9)
    # two rounded points per line still land close
    res3 = pose_from_points(rounded, f, D, (319.5, 239.5), camera_offset_m=pose.camera_offset_m)
    assert res3.found and res3.height_m == pytest.approx(pose.height_m, rel=0.03)


def test_lines_that_do_not_close_are_not_a_runway():
    pts = {
        "horizon": [[0.0, 200.0], [639.0, 200.0]],
        "left_edge": [[250.0, 260.0], [100.0, 470.0]],  # these two meet 40 px below the horizon
        "right_edge": [[390.0, 260.0], [540.0, 470.0]],
    }
    res = pose_from_points(pts, 554.0, D, (319.5, 239.5))
    assert not res.found and "misclosure" in res.reason


_EDGES = {"left_edge": [[1, 300], [2, 400]], "right_edge": [[5, 300], [9, 400]]}


@pytest.mark.parametrize(
    "points, message",
    [
        ({"horizon": [[0, 200]], **_EDGES}, "at least two"),
        ({"horizon": [[0, 200], [9, "x"]], **_EDGES}, "pairs"),
        ({"horizon": [[0, 200], [0.2, 200.1]], **_EDGES}, "span"),
        ({"horizon": [[0, 200], [600, 200]], **_EDGES, "left_edge": [[1, 100], [2, 400]]},
         "below the horizon"),
        ({"horizon": [[0, 200], [600, float("nan")]], **_EDGES}, "finite"),
        ({"horizon": [[0, 200], [600, 200]], "left_edge": [[1, 300], [2, 400]]}, "right_edge"),
    ],
)
def test_bad_points_raise_vision_error(points, message):
    with pytest.raises(VisionError, match=message):
        pose_from_points(points, 554.0, D, (319.5, 239.5))


def test_load_points_file(tmp_path):
    good = {"horizon": [[0, 200], [600, 210]], "left_edge": [[300, 230], [100, 470]],
            "right_edge": [[330, 230], [520, 470]]}
    p = tmp_path / "pts.json"
    p.write_text(json.dumps(good))
    pts = load_points(p)
    assert set(pts) == {"horizon", "left_edge", "right_edge"} and pts["horizon"].shape == (2, 2)
    with pytest.raises(VisionError, match="not found"):
        load_points(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(VisionError, match="not valid JSON"):
        load_points(tmp_path / "bad.json")
    (tmp_path / "list.json").write_text("[1, 2]")
    with pytest.raises(VisionError, match="JSON object"):
        load_points(tmp_path / "list.json")
    (tmp_path / "partial.json").write_text(json.dumps({"horizon": good["horizon"]}))
    with pytest.raises(VisionError, match="lacks left_edge, right_edge"):
        load_points(tmp_path / "partial.json")
