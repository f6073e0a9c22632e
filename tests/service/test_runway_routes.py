"""Runway vision through the service and the dashboard panel (upload, overlay, manual clicks)."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest

from radar_io.benchmarks.service_load import ServeProcess
from radar_io.vision.synth import RunwayPose, expected_lines, focal_for_fov, render_runway

from .cdp import Chrome
from .test_live_pty import ARTIFACTS

W, H = 640, 480
F = focal_for_fov(W, 60.0)
POSE = RunwayPose(bank_deg=5.0, pitch_deg=-4.0, yaw_deg=3.0, height_m=60.0, lateral_m=10.0)


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    s = ServeProcess("sim://", tmp_path_factory.mktemp("rw") / "data")
    s.wait_ready()
    yield s
    s.stop()


def post(svc, path: str, body: bytes, ctype: str) -> tuple[int, dict]:
    req = urllib.request.Request(svc.base + path, data=body, method="POST",
                                 headers={"Content-Type": ctype})
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def close_to_truth(doc: dict) -> None:
    assert doc["found"], doc
    assert doc["bank_deg"] == pytest.approx(POSE.bank_deg, abs=0.3)
    assert doc["pitch_deg"] == pytest.approx(POSE.pitch_deg, abs=0.3)
    assert doc["yaw_deg"] == pytest.approx(POSE.yaw_deg, abs=0.3)
    assert doc["height_m"] == pytest.approx(POSE.height_m, rel=0.03)
    assert doc["lateral_m"] == pytest.approx(POSE.lateral_m, abs=0.05 * POSE.height_m + 0.5)


def picked_points() -> dict[str, list[list[float]]]:
    lines = expected_lines(POSE, F, W, H)
    hz = lines["horizon"]
    pts = {"horizon": [[u, -(hz[0] * u + hz[2]) / hz[1]] for u in (80.0, 320.0, 560.0)]}
    v_h = -(hz[0] * 320 + hz[2]) / hz[1]
    for name in ("left_edge", "right_edge"):
        a, b, c = lines[name]
        pts[name] = [[-(b * v + c) / a, v] for v in (v_h + 60, v_h + 120, v_h + 180)]
    return pts


def test_upload_an_image(svc):
    img = render_runway(POSE, W, H, F)
    ok, png = cv2.imencode(".png", img)
    code, doc = post(svc, f"/api/runway?focal_px={F}&half_width_m=22.5", png.tobytes(), "image/png")
    assert code == 200, doc
    close_to_truth(doc)
    overlay = cv2.imdecode(np.frombuffer(__import__("base64").b64decode(doc["overlay_png_base64"]),
                                         np.uint8), cv2.IMREAD_COLOR)
    assert overlay.shape == (H, W, 3)
    assert set(doc["lines"]) == {"horizon", "left_edge", "right_edge"}


def test_no_runway_and_bad_uploads(svc):
    sky = np.full((H, W), 200, np.uint8)
    _, png = cv2.imencode(".png", sky)
    code, doc = post(svc, f"/api/runway?focal_px={F}&half_width_m=22.5", png.tobytes(), "image/png")
    assert code == 200 and doc["found"] is False and doc["reason"]
    code, doc = post(svc, f"/api/runway?focal_px={F}&half_width_m=22.5", b"not an image", "image/png")
    assert code == 422 and "cannot decode" in doc["detail"][0]["msg"]  # one error shape: a list
    code, doc = post(svc, "/api/runway?half_width_m=22.5", png.tobytes(), "image/png")
    assert code == 422 and "focal_px" in json.dumps(doc)


def test_upload_a_frame_sequence(svc, tmp_path):
    p = tmp_path / "seq.avi"
    vw = cv2.VideoWriter(str(p), cv2.VideoWriter_fourcc(*"MJPG"), 5, (W, H), False)
    for k in range(4):
        vw.write(render_runway(RunwayPose(5.0, -4.0, 3.0, 60.0 - 2 * k, 10.0), W, H, F))
    vw.release()
    code, doc = post(svc, f"/api/runway?focal_px={F}&half_width_m=22.5", p.read_bytes(),
                     "video/x-msvideo")
    assert code == 200, doc
    assert len(doc["frames"]) == 4 and doc["found"] == 4
    assert [r["height_m"] for r in doc["frames"]] == pytest.approx([60, 58, 56, 54], rel=0.03)


def test_manual_points(svc):
    body = json.dumps({"points": picked_points(), "focal_px": F, "half_width_m": 22.5,
                       "principal_point": [W / 2, H / 2]}).encode()
    code, doc = post(svc, "/api/runway/manual", body, "application/json")
    assert code == 200, doc
    close_to_truth(doc)
    bad = json.dumps({"points": {"horizon": [[1, 2]]}, "focal_px": F, "half_width_m": 22.5,
                      "principal_point": [W / 2, H / 2]}).encode()
    code, doc = post(svc, "/api/runway/manual", bad, "application/json")
    assert code == 422


def test_dashboard_panel_upload_and_clicks(svc, tmp_path):
    img_path = tmp_path / "runway.png"
    cv2.imwrite(str(img_path), render_runway(POSE, W, H, F))
    chrome = Chrome(tmp_path / "chrome")
    try:
        chrome.navigate(svc.base + "/")
        chrome.eval(f"document.getElementById('rw-f').value = '{F}'")
        doc = chrome.call("DOM.getDocument")
        node = chrome.call("DOM.querySelector", nodeId=doc["root"]["nodeId"], selector="#rw-file")
        chrome.call("DOM.setFileInputFiles", files=[str(img_path)], nodeId=node["nodeId"])
        chrome.wait_for("runwayState.img !== null")
        chrome.eval("document.getElementById('rw-go').click(), true")
        chrome.wait_for("runwayState.result && runwayState.result.found", 30)
        close_to_truth(chrome.eval("runwayState.result"))
        chrome.wait_for("document.getElementById('rw-result').textContent.includes('bank')")
        chrome.screenshot(ARTIFACTS / "dashboard-runway.png")
        # manual mode: an operator clicks three points on each line
        chrome.eval("document.getElementById('rw-clear').click(), "
                    "document.getElementById('rw-canvas').scrollIntoView(), true")
        for name, pts in picked_points().items():
            chrome.eval(f"document.getElementById('rw-line').value = '{name}'")
            rect = chrome.eval("(r => [r.left, r.top, r.width])(document.getElementById("
                               "'rw-canvas').getBoundingClientRect())")
            k = rect[2] / W
            for x, y in pts:
                for kind in ("mousePressed", "mouseReleased"):
                    chrome.call("Input.dispatchMouseEvent", type=kind, x=rect[0] + x * k,
                                y=rect[1] + y * k, button="left", clickCount=1)
        assert chrome.eval("runwayState.points.left_edge.length") == 3
        chrome.eval("runwayState.result = null, document.getElementById('rw-manual').click(), true")
        chrome.wait_for("runwayState.result && runwayState.result.found", 30)
        close_to_truth(chrome.eval("runwayState.result"))
        chrome.screenshot(ARTIFACTS / "dashboard-runway-manual.png")
    finally:
        chrome.close()
