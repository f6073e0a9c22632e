"""The live service while a runway video job runs: ``/api/status`` latency and websocket
loss (issue 10: a video used to freeze the event loop).

``python -m radar_io.benchmarks.runway_service --frames 2000 --clients 5`` starts
``radar-io serve`` on the 1 kHz simulator, renders a 640×480 MJPG video, posts it as a
job, and while the job runs polls ``/api/status`` every 50 ms and reads ``/ws/live`` on
N clients. Prints one JSON line: job time, status p50/p99/max latency, and per client
the messages received and the ones missing by ``msg_seq``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

from radar_io.benchmarks.service_load import ServeProcess

TOKEN = "bench-token"


def make_video(path: Path, frames: int, width: int = 640, height: int = 480) -> float:
    """An MJPG video of a runway approach (20 distinct frames cycled); returns focal_px."""
    import cv2

    from radar_io.vision.synth import RunwayPose, focal_for_fov, render_runway

    f = focal_for_fov(width, 60.0)
    imgs = [render_runway(RunwayPose(5.0, -4.0, 3.0, 60.0 - k, 10.0), width, height, f)
            for k in range(20)]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 25, (width, height), False)
    for i in range(frames):
        vw.write(imgs[i % 20])
    vw.release()
    return f


def run(frames: int, clients: int) -> dict[str, Any]:
    import websockets

    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "v.avi"
        f = make_video(video, frames)
        cfg = Path(tmp) / "serve.toml"
        cfg.write_text("max_upload_mb = 4096\nauto_record = \"manual\"\n")
        svc = ServeProcess("sim://", Path(tmp) / "data", extra=("--config", str(cfg)),
                           env={"RADAR_IO_TOKEN": TOKEN})
        stop = threading.Event()
        lat_ms: list[float] = []
        seqs: list[list[int]] = [[] for _ in range(clients)]

        def poll() -> None:
            while not stop.is_set():
                t = time.perf_counter()
                svc.get("/api/status")
                lat_ms.append((time.perf_counter() - t) * 1e3)
                time.sleep(0.05)

        async def reader(k: int) -> None:
            async with websockets.connect(svc.base.replace("http", "ws") + "/ws/live",
                                          max_size=None) as ws:
                while not stop.is_set():
                    try:
                        text = await asyncio.wait_for(ws.recv(), 1.0)
                    except TimeoutError:
                        continue
                    doc = json.loads(text)
                    for m in doc if isinstance(doc, list) else [doc]:
                        seqs[k].append(m["msg_seq"])

        async def readers() -> None:
            await asyncio.gather(*(reader(k) for k in range(clients)))

        try:
            svc.wait_ready()
            threads = [threading.Thread(target=poll),
                       threading.Thread(target=lambda: asyncio.run(readers()))]
            for t in threads:
                t.start()
            time.sleep(1.0)
            req = urllib.request.Request(
                f"{svc.base}/api/runway?focal_px={f}&half_width_m=22.5", data=video.read_bytes(),
                method="POST", headers={"Content-Type": "video/x-msvideo",
                                        "Authorization": f"Bearer {TOKEN}"})
            t0 = time.monotonic()
            with urllib.request.urlopen(req, timeout=600) as r:
                job = json.loads(r.read())
            while True:
                st = svc.get(job["status_url"])
                if st["state"] in ("done", "failed", "cancelled"):
                    break
                time.sleep(0.2)
            job_s = time.monotonic() - t0
            time.sleep(0.5)
        finally:
            stop.set()
            for t in threads:
                t.join(30)
            svc.stop()
    lat = np.array(lat_ms)
    per_client = []
    for s in seqs:
        a = np.array(s)
        missing = int(a[-1] - a[0] + 1 - len(np.unique(a))) if len(a) else 0
        per_client.append({"messages": len(s), "missing": missing})
    return {"video_frames": frames, "job_state": st["state"], "frames_done": st["frames_done"],
            "job_s": round(job_s, 1), "status_requests": len(lat),
            "status_p50_ms": round(float(np.percentile(lat, 50)), 1),
            "status_p99_ms": round(float(np.percentile(lat, 99)), 1),
            "status_max_ms": round(float(lat.max()), 1), "clients": per_client}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument("--clients", type=int, default=5)
    a = ap.parse_args()
    print(json.dumps(run(a.frames, a.clients)))


if __name__ == "__main__":
    main()
