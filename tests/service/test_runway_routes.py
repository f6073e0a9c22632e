"""Runway vision through the service and the dashboard panel (upload, overlay, manual clicks),
video jobs (202 / state / cancel / 429), the token, and the streamed size limit (413)."""

from __future__ import annotations

import asyncio
import json
import select
import socket
import threading
import time
import urllib.error
import urllib.request
from itertools import pairwise

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
TOKEN = "rw-token"
LIMIT_MB = 32
Q = f"/api/runway?focal_px={F}&half_width_m=22.5"


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    d = tmp_path_factory.mktemp("rw")
    cfg = d / "serve.toml"
    cfg.write_text(f"max_upload_mb = {LIMIT_MB}\nrunway_queue = 2\n")
    s = ServeProcess("sim://", d / "data", extra=("--config", str(cfg)),
                     env={"RADAR_IO_TOKEN": TOKEN})
    s.wait_ready()
    yield s
    s.stop()


@pytest.fixture(scope="module")
def long_video(tmp_path_factory):
    """600 frames, 640×480 MJPG (about 19 MB): some seconds of work for the tracker."""
    p = tmp_path_factory.mktemp("video") / "long.avi"
    imgs = [render_runway(RunwayPose(5.0, -4.0, 3.0, 60.0 - k, 10.0), W, H, F) for k in range(20)]
    vw = cv2.VideoWriter(str(p), cv2.VideoWriter_fourcc(*"MJPG"), 25, (W, H), False)
    for i in range(600):
        vw.write(imgs[i % 20])
    vw.release()
    return p.read_bytes()


def request(svc, method: str, path: str, body: bytes | None = None, ctype: str | None = None,
            token: str | None = TOKEN) -> tuple[int, dict]:
    headers = {"Content-Type": ctype} if ctype else {}
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    req = urllib.request.Request(svc.base + path, data=body, method=method, headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def post(svc, path: str, body: bytes, ctype: str, token: str | None = TOKEN) -> tuple[int, dict]:
    return request(svc, "POST", path, body, ctype, token)


def wait_job(svc, job: str, states=("done", "failed", "cancelled"), timeout_s: float = 120) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        code, doc = request(svc, "GET", f"/api/runway/jobs/{job}")
        assert code == 200, doc
        if doc["state"] in states:
            return doc
        assert time.monotonic() < deadline, doc
        time.sleep(0.05)


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
    _, png = cv2.imencode(".png", img)
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
    code, doc = post(svc, Q, png.tobytes(), "image/png")
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
    code, doc = post(svc, Q, p.read_bytes(), "video/x-msvideo")
    assert code == 202, doc
    assert doc["status_url"] == f"/api/runway/jobs/{doc['job']}"
    job = wait_job(svc, doc["job"])
    assert job["state"] == "done" and job["error"] is None, job
    assert job["frames_done"] == job["frames_total"] == 4
    res = job["result"]
    assert len(res["frames"]) == 4 and res["found"] == 4
    assert [r["height_m"] for r in res["frames"]] == pytest.approx([60, 58, 56, 54], rel=0.03)
    # a broken video fails the job with a reason, and the service carries on
    code, doc = post(svc, Q, b"\x00" * 1000, "video/mp4")
    assert code == 202
    job = wait_job(svc, doc["job"])
    assert job["state"] == "failed" and "cannot decode" in job["error"]
    code, doc = request(svc, "GET", "/api/runway/jobs/nosuchjob")
    assert code == 404


def test_uploads_need_the_token(svc):
    _, png = cv2.imencode(".png", render_runway(POSE, W, H, F))
    code, doc = post(svc, Q, png.tobytes(), "image/png", token=None)
    assert code == 401 and "Bearer" in doc["detail"][0]["msg"]
    code, doc = post(svc, Q, png.tobytes(), "image/png", token="wrong")
    assert code == 403
    code, doc = request(svc, "DELETE", "/api/runway/jobs/x", token=None)
    assert code == 401


def raw_http(svc, head: str) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", svc.port), timeout=30)
    s.sendall(head.encode())
    return s


def read_response(s: socket.socket) -> tuple[int, dict]:
    buf = b""
    while b"\r\n\r\n" not in buf:
        piece = s.recv(65536)
        assert piece, buf
        buf += piece
    head, _, body = buf.partition(b"\r\n\r\n")
    length = int(next(ln.split(b":")[1] for ln in head.split(b"\r\n")
                      if ln.lower().startswith(b"content-length")))
    while len(body) < length:
        body += s.recv(65536)
    return int(head.split()[1]), json.loads(body)


def test_declared_oversize_body_is_refused_before_it_is_sent(svc):
    size = (LIMIT_MB << 20) + 1
    s = raw_http(svc, f"POST {Q} HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
                      f"Content-Type: image/png\r\nContent-Length: {size}\r\n\r\n")
    try:
        code, doc = read_response(s)  # not one body byte sent
    finally:
        s.close()
    assert code == 413 and str(size) in doc["detail"][0]["msg"]


def test_streamed_oversize_body_is_refused_while_reading(svc):
    s = raw_http(svc, f"POST {Q} HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
                      "Content-Type: video/mp4\r\nTransfer-Encoding: chunked\r\n\r\n")
    piece = b"\x00" * (1 << 20)
    chunk = f"{len(piece):x}\r\n".encode() + piece + b"\r\n"
    sent = 0
    try:
        while sent < 4 * LIMIT_MB:  # never sends the end of the body
            if select.select([s], [], [], 0)[0]:
                break
            try:
                s.sendall(chunk)
            except (BrokenPipeError, ConnectionResetError):
                break
            sent += 1
        code, doc = read_response(s)
    finally:
        s.close()
    assert code == 413 and "more than" in doc["detail"][0]["msg"]
    assert LIMIT_MB <= sent < 4 * LIMIT_MB  # answered after the limit, long before the end


def test_queue_full_429_and_cancel(svc, long_video):
    jobs = []
    for _ in range(3):  # one runs, two wait
        code, doc = post(svc, Q, long_video, "video/x-msvideo")
        assert code == 202, doc
        jobs.append(doc["job"])
    # a fourth: 429, answered from the headers, before the body is sent
    s = raw_http(svc, f"POST {Q} HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
                      f"Content-Type: video/x-msvideo\r\nContent-Length: {len(long_video)}\r\n\r\n")
    try:
        code, doc = read_response(s)
    finally:
        s.close()
    assert code == 429 and "queue full" in doc["detail"][0]["msg"]
    # cancel a waiting job: at once
    code, doc = request(svc, "DELETE", f"/api/runway/jobs/{jobs[2]}")
    assert code == 200 and doc["state"] == "cancelled" and doc["frames_done"] == 0
    # cancel the running one once it has made progress: stops at its next frame
    wait_until = time.monotonic() + 60
    while (running := request(svc, "GET", f"/api/runway/jobs/{jobs[0]}")[1])["frames_done"] < 5:
        assert time.monotonic() < wait_until
        time.sleep(0.05)
    assert running["state"] == "running" and running["frames_total"] == 600
    code, doc = request(svc, "DELETE", f"/api/runway/jobs/{jobs[0]}")
    assert code == 200
    done = wait_job(svc, jobs[0])
    assert done["state"] == "cancelled" and 5 <= done["frames_done"] < 600
    assert done["result"] is None
    # the next job starts; cancel it too
    wait_job(svc, jobs[1], states=("running",))
    request(svc, "DELETE", f"/api/runway/jobs/{jobs[1]}")
    assert wait_job(svc, jobs[1])["state"] == "cancelled"


def test_service_keeps_answering_during_a_long_job(svc, long_video):
    """While the tracker works through 600 frames, /api/status and a websocket keep
    answering (today's code ran OpenCV on the event loop: nothing answered until the end).
    The largest gaps are printed (figures, not asserts)."""
    import websockets

    stop = threading.Event()
    status_times: list[float] = []
    ws_times: list[float] = []

    def poll_status() -> None:
        while not stop.is_set():
            svc.get("/api/status")
            status_times.append(time.monotonic())
            time.sleep(0.01)

    async def ws_reader() -> None:
        async with websockets.connect(svc.base.replace("http", "ws") + "/ws/live",
                                      max_size=None) as ws:
            while not stop.is_set():
                try:
                    await asyncio.wait_for(ws.recv(), 1.0)
                except TimeoutError:
                    continue
                ws_times.append(time.monotonic())

    threads = [threading.Thread(target=poll_status),
               threading.Thread(target=lambda: asyncio.run(ws_reader()))]
    for t in threads:
        t.start()
    try:
        time.sleep(5)  # a baseline without a job, for the printed figures
        b1 = time.monotonic()
        code, doc = post(svc, Q, long_video, "video/x-msvideo")
        assert code == 202, doc
        wait_job(svc, doc["job"], states=("running",))
        t0 = time.monotonic()
        job = wait_job(svc, doc["job"])
        t1 = time.monotonic()
    finally:
        stop.set()
        for t in threads:
            t.join(30)
    assert job["state"] == "done" and job["frames_done"] == 600
    assert job["result"]["found"] == 600
    during_status = [t for t in status_times if t0 <= t <= t1]
    during_ws = [t for t in ws_times if t0 <= t <= t1]
    assert len(during_status) >= 10 and len(during_ws) >= 1000  # the sim runs at 1 kHz

    def max_gap(ts: list[float]) -> float:
        return max(b - a for a, b in pairwise(ts)) * 1e3

    base_s = [t for t in status_times if t <= b1]
    base_w = [t for t in ws_times if t <= b1]
    print(f"\nbaseline 5 s without a job: /api/status max gap {max_gap(base_s):.0f} ms, "
          f"websocket max gap {max_gap(base_w):.0f} ms")
    print(f"runway job 600 frames in {t1 - t0:.1f} s: /api/status answered "
          f"{len(during_status)} times, max gap {max_gap(during_status):.0f} ms; "
          f"websocket {len(during_ws)} messages, max gap {max_gap(during_ws):.0f} ms")


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
        chrome.eval(f"document.getElementById('token').value = '{TOKEN}'")
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
