"""Runway video jobs with real child processes: a child that floods its stderr still
finishes (or fails cleanly) and frees the worker; a child over the job's wall-clock limit
is killed and the job says so. The job runner's child command is pointed at small scripts
written here (``RunwayJobs(command=…)``); the last test runs the real vision worker on a
video too long for its ``runway_job_timeout_s``."""

from __future__ import annotations

import json
import sys
import time
import urllib.request
from pathlib import Path

import cv2
import pytest

from radar_io.service.runway_jobs import RunwayJob, RunwayJobs
from radar_io.vision.synth import RunwayPose, focal_for_fov, render_runway

from .liveserver import TOKEN, live_server, service_config

#: a child that talks the worker's protocol on stdout and writes ``MiB`` MiB to stderr first
FLOOD = """
import json, sys
mib, status = float(sys.argv[1]), int(sys.argv[2])
line = ("libav: corrupt macroblock at 12 34, concealing errors " * 4 + "\\n").encode()
n = 0
while n < mib * (1 << 20):
    sys.stderr.buffer.write(line)
    n += len(line)
sys.stderr.buffer.write(b"the last complaint of the decoder\\n")
sys.stderr.flush()
print(json.dumps({"frames_total": 2}), flush=True)
for k in range(2):
    print(json.dumps({"frame": k, "found": True}), flush=True)
sys.exit(status)
"""

#: a child that reports one frame, then hangs (ignoring SIGTERM)
HANG = """
import json, signal, sys, time
signal.signal(signal.SIGTERM, signal.SIG_IGN)
print(json.dumps({"frames_total": None}), flush=True)
print(json.dumps({"frame": 0, "found": False}), flush=True)
while True:
    time.sleep(1)
"""


def wait_final(jobs: RunwayJobs, job: RunwayJob, timeout_s: float = 60.0) -> RunwayJob:
    deadline = time.monotonic() + timeout_s
    while jobs.get(job.id).state not in ("done", "failed", "cancelled"):
        assert time.monotonic() < deadline, job.as_dict()
        time.sleep(0.02)
    return job


@pytest.fixture
def scripts(tmp_path: Path) -> dict[str, Path]:
    out = {}
    for name, text in (("flood", FLOOD), ("hang", HANG)):
        out[name] = tmp_path / f"{name}.py"
        out[name].write_text(text)
    return out


def _spool(jobs: RunwayJobs, text: str) -> Path:
    """An "upload" whose text tells the command below how the child behaves."""
    p = jobs.new_spool_path()
    p.write_text(text)
    return p


def test_stderr_flood_neither_hangs_the_job_nor_the_worker(tmp_path, scripts):
    """2 MiB on stderr (a pipe holds 64 KiB): the job completes, a flooding child that
    fails shows the last line of its stderr, and the next job runs."""

    def command(job: RunwayJob, max_frames: int) -> list[str]:
        mib, status = job.video.read_text().split()
        return [sys.executable, str(scripts["flood"]), mib, status]

    jobs = RunwayJobs(max_queued=3, spool_dir=tmp_path, timeout_s=60.0, command=command)
    try:
        ok = jobs.submit(_spool(jobs, "2 0"), 500.0, 22.5, None)
        bad = jobs.submit(_spool(jobs, "2 3"), 500.0, 22.5, None)
        nxt = jobs.submit(_spool(jobs, "0 0"), 500.0, 22.5, None)
        for job in (ok, bad, nxt):
            wait_final(jobs, job)
        assert ok.state == "done" and ok.frames_done == 2, ok.as_dict()
        assert ok.result is not None and ok.result["found"] == 2
        assert bad.state == "failed", bad.as_dict()
        assert bad.error == "runway worker failed: the last complaint of the decoder"
        assert nxt.state == "done", nxt.as_dict()
        assert jobs.stats()["running"] == 0
        # the uploads and the stderr files are gone
        assert list(jobs.spool_dir.iterdir()) == []
    finally:
        jobs.close()


def test_a_job_over_its_time_limit_is_killed_and_reported(tmp_path, scripts):
    def command(job: RunwayJob, max_frames: int) -> list[str]:
        name = job.video.read_text()
        return [sys.executable, str(scripts[name])] + (["0", "0"] if name == "flood" else [])

    jobs = RunwayJobs(max_queued=2, spool_dir=tmp_path, timeout_s=1.5, command=command)
    try:
        hung = jobs.submit(_spool(jobs, "hang"), 500.0, 22.5, None)
        after = jobs.submit(_spool(jobs, "flood"), 500.0, 22.5, None)
        t0 = time.monotonic()
        wait_final(jobs, hung)
        took_s = time.monotonic() - t0
        assert hung.state == "failed", hung.as_dict()
        assert "time limit of 1.5 s" in (hung.error or "") and "after 1 frames" in hung.error
        assert hung.frames_done == 1 and hung.result is None
        # SIGTERM is ignored by this child: killed after the grace period, not later
        assert 1.5 <= took_s < 15.0
        wait_final(jobs, after)
        assert after.state == "done", after.as_dict()
    finally:
        jobs.close()


def test_the_service_stops_a_real_job_at_runway_job_timeout_s(tmp_path):
    """Through the service, with the real vision worker: a 400-frame video under a 1 s limit
    (the tracker needs several seconds for it) fails saying so, and the next upload runs."""
    w, h = 640, 480
    f = focal_for_fov(w, 60.0)
    video = tmp_path / "long.avi"
    img = render_runway(RunwayPose(5.0, -4.0, 3.0, 60.0, 10.0), w, h, f)
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25, (w, h), False)
    for _ in range(400):
        vw.write(img)
    vw.release()
    body = video.read_bytes()

    def call(srv, method: str, path: str, data: bytes | None = None) -> dict:
        req = urllib.request.Request(srv.base + path, data=data, method=method, headers={
            "Authorization": f"Bearer {TOKEN}", "Content-Type": "video/x-msvideo"})
        with urllib.request.urlopen(req, timeout=60) as r:
            return json.loads(r.read())

    def final(srv, job: str) -> dict:
        deadline = time.monotonic() + 60
        while (doc := call(srv, "GET", f"/api/runway/jobs/{job}"))["state"] in ("queued",
                                                                                "running"):
            assert time.monotonic() < deadline, doc
            time.sleep(0.05)
        return doc

    cfg = service_config(tmp_path / "svc", runway_job_timeout_s=1.0)
    with live_server(cfg) as srv:
        q = f"/api/runway?focal_px={f}&half_width_m=22.5"
        slow = final(srv, call(srv, "POST", q, body)["job"])
        assert slow["state"] == "failed", slow
        assert "time limit of 1 s (runway_job_timeout_s)" in slow["error"]
        assert slow["frames_done"] < 400 and slow["result"] is None
        # the worker is free: the next job starts (and meets the same limit)
        nxt = final(srv, call(srv, "POST", q, body)["job"])
        assert nxt["state"] == "failed" and nxt["frames_done"] < 400
