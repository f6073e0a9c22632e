"""The manual runway pose in Chromium uses the Python pipeline's image centre
((W − 1) / 2, (H − 1) / 2) and pixel coordinates with 0 at the first pixel's centre; the
pose the dashboard shows is the one Python computes from the same points."""

from __future__ import annotations

import cv2
import pytest

from radar_io.vision.manual import pose_from_points
from radar_io.vision.synth import RunwayPose, expected_lines, focal_for_fov, render_runway

from .liveserver import browser, sim_server  # noqa: F401
from .test_live_pty import ARTIFACTS

W, H = 640, 480
F = focal_for_fov(W, 60.0)
POSE = RunwayPose(bank_deg=4.0, pitch_deg=-3.0, yaw_deg=2.0, height_m=80.0, lateral_m=-6.0)


def picked_points() -> dict[str, list[list[float]]]:
    lines = expected_lines(POSE, F, W, H)
    hz = lines["horizon"]
    pts = {"horizon": [[u, -(hz[0] * u + hz[2]) / hz[1]] for u in (100.0, 320.0, 540.0)]}
    v_h = -(hz[0] * 320 + hz[2]) / hz[1]
    for name in ("left_edge", "right_edge"):
        a, b, c = lines[name]
        pts[name] = [[-(b * v + c) / a, v] for v in (v_h + 50, v_h + 110, v_h + 170)]
    return pts


def test_manual_pose_principal_point_matches_python(sim_server, browser, tmp_path):  # noqa: F811
    img_path = tmp_path / "runway.png"
    cv2.imwrite(str(img_path), render_runway(POSE, W, H, F))
    browser.navigate(sim_server.base + "/")
    assert browser.eval(f"import('/static/js/runway.js').then(m => m.principalPoint({W}, {H}))") \
        == [(W - 1) / 2, (H - 1) / 2]
    browser.eval(f"document.getElementById('rw-f').value = '{F}', true")
    doc = browser.call("DOM.getDocument")
    node = browser.call("DOM.querySelector", nodeId=doc["root"]["nodeId"], selector="#rw-file")
    browser.call("DOM.setFileInputFiles", files=[str(img_path)], nodeId=node["nodeId"])
    browser.wait_for("runwayState.img !== null")
    browser.eval("document.getElementById('rw-canvas').scrollIntoView(), true")
    want = picked_points()
    rect_js = ("(c => { const r = c.getBoundingClientRect(); return [r.left + c.clientLeft, "
               "r.top + c.clientTop, c.clientWidth]; })(document.getElementById('rw-canvas'))")
    for name, pts in want.items():
        browser.eval(f"document.getElementById('rw-line').value = '{name}'")
        for u, v in pts:  # pixel (u, v) is the square [u, u + 1) × [v, v + 1) on the canvas
            left, top, width = browser.eval(rect_js)  # per click: live text may shift the page
            k = width / W  # CSS px per image pixel, inside the canvas's border
            for kind in ("mousePressed", "mouseReleased"):
                browser.call("Input.dispatchMouseEvent", type=kind, x=left + (u + 0.5) * k,
                             y=top + (v + 0.5) * k, button="left", clickCount=1)
    picked = browser.eval("runwayState.points")
    for name, pts in want.items():  # clicks land on the pixel aimed at: mouse events carry
        # whole CSS pixels, and the page may move by a pixel between measuring and clicking
        assert picked[name] == [pytest.approx(p, abs=2.0 / k) for p in pts]
    browser.eval("runwayState.result = null, document.getElementById('rw-manual').click(), true")
    browser.wait_for("runwayState.result !== null", 30)
    sent = browser.eval("runwayState.lastManual")
    assert sent["principal_point"] == [(W - 1) / 2, (H - 1) / 2]
    shown = browser.eval("runwayState.result")
    assert shown["found"]

    # the same points through Python: identical pose with (W−1)/2, a different one with W/2
    python = pose_from_points(sent["points"], F, 22.5, ((W - 1) / 2, (H - 1) / 2)).to_dict()
    for key in ("bank_deg", "pitch_deg", "yaw_deg", "height_m", "lateral_m"):
        assert shown[key] == python[key], key
    old = pose_from_points(sent["points"], F, 22.5, (W / 2, H / 2)).to_dict()
    assert any(old[k] != python[k] for k in ("pitch_deg", "yaw_deg", "lateral_m"))
    assert shown["yaw_deg"] == pytest.approx(POSE.yaw_deg, abs=0.3)
    browser.screenshot(ARTIFACTS / "dashboard-principal-point.png")
