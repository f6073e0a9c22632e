"""``radar-io runway`` end to end, as a subprocess on PNG/AVI files written to tmp_path."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from radar_io.vision.synth import RunwayPose, RunwayScene, focal_for_fov, render_runway

RADAR_IO = (sys.executable, "-m", "radar_io.cli")  # the console script's entry point
F = focal_for_fov(640)
POSE = RunwayPose(6.0, -4.0, 3.0, 45.0, -8.0)


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*RADAR_IO, "runway", *args], capture_output=True, text=True, timeout=120)


def _camera(*extra: str) -> list[str]:
    return ["--focal-px", f"{F:.6f}", "--half-width-m", "22.5", *extra]


def _close_to(rec: dict, pose: RunwayPose) -> None:
    assert rec["found"] is True
    assert rec["bank_deg"] == pytest.approx(pose.bank_deg, abs=0.3)
    assert rec["pitch_deg"] == pytest.approx(pose.pitch_deg, abs=0.3)
    assert rec["yaw_deg"] == pytest.approx(pose.yaw_deg, abs=0.3)
    assert rec["height_m"] == pytest.approx(pose.height_m, rel=0.03)
    assert rec["lateral_m"] == pytest.approx(pose.lateral_m, abs=0.05 * pose.height_m + 0.5)
    assert 0.0 < rec["quality"] <= 1.0


@pytest.fixture(scope="module")
def images(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("runway")
    out = {}
    out["runway"] = d / "runway.png"
    cv2.imwrite(str(out["runway"]), render_runway(POSE, 640, 480, F, RunwayScene(seed=1)))
    out["sky"] = d / "sky.png"
    cv2.imwrite(str(out["sky"]),
                render_runway(RunwayPose(0.0, 40.0, 0.0, 50.0, 0.0), 640, 480, F, RunwayScene(seed=2)))
    out["junk"] = d / "junk.png"
    out["junk"].write_bytes(b"this is not a PNG")
    return out


@pytest.mark.slow
def test_images_to_json_lines(images):
    r = _run(str(images["runway"]), str(images["sky"]), *_camera())
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 2
    first, second = (json.loads(x) for x in lines)
    assert first["image"] == str(images["runway"])
    _close_to(first, POSE)
    assert "reason" not in first
    assert second["image"] == str(images["sky"])
    assert second["found"] is False and second["reason"] and second["height_m"] is None
    assert second["quality"] == 0.0


@pytest.mark.slow
def test_principal_point_and_camera_offset_options(images):
    base = json.loads(_run(str(images["runway"]), *_camera()).stdout)
    r = _run(str(images["runway"]), *_camera("--principal-point", "319.5,219.5", "--camera-offset", "5,0,-1"))
    assert r.returncode == 0, r.stderr
    moved = json.loads(r.stdout)
    # principal point 20 px higher: the same horizon is seen 20 px lower relative to it
    assert moved["pitch_deg"] == pytest.approx(base["pitch_deg"] + np.degrees(np.arctan2(20.0, F)), abs=0.05)
    # the offset (and the pitch) change the height
    assert moved["height_m"] != pytest.approx(base["height_m"], abs=0.1)


@pytest.mark.slow
def test_manual_points(images, tmp_path):
    # exact picks of the rendered pose: horizon from two directions, edges from ground points
    from radar_io.vision import pose_equations as g

    pp = (319.5, 239.5)
    b, p, y = POSE.angles_rad
    cam = POSE.camera_position()

    def pix(points, camera):
        x, yy, _ = g.project_points(np.asarray(points, float), camera, b, p, y, F)
        return np.stack(g.image_to_pixel(x, yy, pp), -1).round(2).tolist()

    dirs = [[np.cos(y + a), np.sin(y + a), 0.0] for a in (-0.4, 0.4)]
    doc = {
        "horizon": pix(dirs, np.zeros(3)),
        "left_edge": pix([[300.0, -22.5, 0.0], [1500.0, -22.5, 0.0]], cam),
        "right_edge": pix([[300.0, 22.5, 0.0], [1500.0, 22.5, 0.0]], cam),
    }
    pts = tmp_path / "points.json"
    pts.write_text(json.dumps(doc))
    r = _run(str(images["runway"]), "--points", str(pts), *_camera())
    assert r.returncode == 0, r.stderr
    rec = json.loads(r.stdout)
    _close_to(rec, POSE)
    assert rec["height_m"] == pytest.approx(POSE.height_m, rel=1e-3)
    # without an image the principal point must be given
    r = _run("--points", str(pts), *_camera())
    assert r.returncode == 2 and "--principal-point" in r.stderr
    r = _run("--points", str(pts), *_camera("--principal-point", "319.5,239.5"))
    assert r.returncode == 0 and json.loads(r.stdout)["image"] is None


@pytest.mark.slow
def test_sequence_from_directory_glob_and_video(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    poses = [RunwayPose(2.0 + i, -3.0, 1.0 - 0.5 * i, 60.0 - 5.0 * i, 3.0 + i) for i in range(4)]
    writer = cv2.VideoWriter(str(tmp_path / "clip.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 480))
    assert writer.isOpened()
    for i, pose in enumerate(poses):
        img = render_runway(pose, 640, 480, F, RunwayScene(seed=10 + i))
        cv2.imwrite(str(frames / f"f{i:03d}.png"), img)
        writer.write(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    writer.release()

    for source in (str(frames), str(frames / "f*.png"), str(tmp_path / "clip.avi")):
        r = _run("--video", source, *_camera())
        assert r.returncode == 0, r.stderr
        recs = [json.loads(x) for x in r.stdout.splitlines()]
        assert [x["frame"] for x in recs] == [0, 1, 2, 3]
        for rec, pose in zip(recs, poses, strict=True):
            _close_to(rec, pose)
        assert "4 frames, runway found in 4" in r.stderr
        assert "Traceback" not in r.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    "args, message",
    [
        (["{missing}"], "image not found"),
        (["{junk}"], "cannot read image"),
        (["{runway}", "--focal-px", "-100", "--half-width-m", "22.5"], "--focal-px must be a positive"),
        (["{runway}", "--focal-px", "500", "--half-width-m", "0"], "--half-width-m must be a positive"),
        (["{runway}", "--principal-point", "320"], "--principal-point must be 2"),
        (["--video", "{missing}"], "video source not found"),
        (["--points", "{junk}", "--principal-point", "1,2"], "not valid JSON"),
        ([], "nothing to do"),
    ],
)
def test_bad_input_gives_one_clear_line(images, tmp_path, args, message):
    subst = {"missing": str(tmp_path / "nope.png"), "junk": str(images["junk"]),
             "runway": str(images["runway"])}
    argv = [a.format(**subst) for a in args]
    if "--focal-px" not in argv:
        argv += _camera()
    r = _run(*argv)
    assert r.returncode == 2
    assert r.stdout == ""
    assert "Traceback" not in r.stderr
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("radar-io: error: ") and message in err[0]
