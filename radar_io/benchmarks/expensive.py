"""Expensive requests against a real ``radar-io serve``: a burst of concurrent flight-report
(or sync-event) requests without a token, while a separate process polls ``/api/status``
and a control call. Shows the limiter's promise: the excess is answered 429 with
Retry-After, the status and control stay fast, the memory of the service and its worker
processes stays bounded.

``python -m radar_io.benchmarks.expensive [--kind report|sync] [--clients 100]
[--recording-s 600]`` or ``radar-io bench --expensive-clients N``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

from radar_io.benchmarks.service_load import ServeProcess, rss_mb

TOKEN = "bench-expensive-token"

#: polls GET status and a harmless control call (POST /api/recordings/stop) alternately every
#: ``every`` s until its stdin closes; prints [wall time, latency ms] of both as JSON
_POLL = """
import json, select, sys, time, urllib.request
base, token, every = sys.argv[1], sys.argv[2], float(sys.argv[3])
lat = {"status": [], "control": []}
k = 0
while not select.select([sys.stdin], [], [], 0)[0]:
    kind = "control" if k % 2 else "status"
    req = urllib.request.Request(base + ("/api/recordings/stop" if k % 2 else "/api/status"),
                                 method="POST" if k % 2 else "GET",
                                 headers={"Authorization": "Bearer " + token})
    t, t0 = time.time(), time.perf_counter()
    try:
        urllib.request.urlopen(req, timeout=30).read()
        lat[kind].append((t, (time.perf_counter() - t0) * 1e3))
    except OSError:
        lat[kind].append((t, float("inf")))
    k += 1
    time.sleep(every)
print(json.dumps(lat))
"""

PATHS = {"report": "/api/recordings/{id}/report", "sync": "/api/sync-events?recording={id}"}


def tree_rss_mb(pid: int) -> float:
    """RSS (MiB) of a process and all its descendants (the service and its workers)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        try:
            total += rss_mb(p)
        except OSError:
            continue
        todo += children.get(p, [])
    return total


def _fire(url: str, start: threading.Barrier, out: list[tuple[int, str | None, float]]) -> None:
    start.wait()
    t0 = time.perf_counter()
    try:
        with urllib.request.urlopen(url, timeout=600) as r:
            r.read()
            out.append((r.status, None, time.perf_counter() - t0))
    except urllib.error.HTTPError as e:
        e.read()
        out.append((e.code, e.headers.get("Retry-After"), time.perf_counter() - t0))
    except OSError:
        out.append((0, None, time.perf_counter() - t0))


def bench_expensive(kind: str = "report", clients: int = 100, recording_s: float = 600.0,
                    poll_every_s: float = 0.02, recording: Path | None = None,
                    baseline_s: float = 3.0) -> dict[str, Any]:
    """``clients`` concurrent ``kind`` requests (``report`` or ``sync``) for one recording of
    ``recording_s`` seconds (simulated, or the ``.rdrlog`` given) on a fresh ``serve``:
    answers by status, Retry-After on every 429, /api/status and control latency (ms)
    meanwhile, and for comparison the status latency during ``baseline_s`` before the
    burst (what the machine's load alone costs); the RSS (MiB) of the service with its
    worker processes, idle and at its peak."""
    with tempfile.TemporaryDirectory() as d:
        data = Path(d) / "data"
        (data / "recordings").mkdir(parents=True)
        rec = data / "recordings" / "bench.rdrlog"
        t_sim = 0.0
        if recording is not None:  # inside the data directory (a symlink out is refused)
            try:
                os.link(recording, rec)
            except OSError:
                shutil.copyfile(recording, rec)
        else:
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "radar_io.cli", "simulate", "-o", str(rec),
                            "--duration-s", str(recording_s), "--sync-every-s", "2", "-q"],
                           check=True)
            t_sim = time.perf_counter() - t0
        cfg = Path(d) / "serve.toml"
        cfg.write_text('auto_record = "manual"\n')
        svc = ServeProcess("sim://", data, extra=("--config", str(cfg)),
                           env={"RADAR_IO_TOKEN": TOKEN})
        try:
            svc.wait_ready()
            time.sleep(2.0)
            rss_idle = tree_rss_mb(svc.proc.pid)
            poll = subprocess.Popen([sys.executable, "-c", _POLL, svc.base, TOKEN,
                                     str(poll_every_s)], stdin=subprocess.PIPE,
                                    stdout=subprocess.PIPE, text=True)
            time.sleep(0.5 + baseline_s)  # the poller's interpreter is up; the baseline
            url = svc.base + PATHS[kind].format(id=rec.stem)
            answers: list[tuple[int, str | None, float]] = []
            start = threading.Barrier(clients)
            threads = [threading.Thread(target=_fire, args=(url, start, answers), daemon=True)
                       for _ in range(clients)]
            t0, t_burst = time.perf_counter(), time.time()
            for t in threads:
                t.start()
            rss_peak = rss_idle
            while any(t.is_alive() for t in threads):
                rss_peak = max(rss_peak, tree_rss_mb(svc.proc.pid))
                time.sleep(0.05)
            burst_s = time.perf_counter() - t0
            t_end = time.time()
            lat = json.loads(poll.communicate(timeout=120)[0])  # closes its stdin: it stops
            limits = svc.get("/api/status")["expensive"]
            rec_mb = rec.stat().st_size / 2**20
        finally:
            svc.stop()
    codes: dict[str, int] = {}
    for code, _, _ in answers:
        codes[str(code)] = codes.get(str(code), 0) + 1
    retry = [r for code, r, _ in answers if code == 429]
    def window(k: str, lo: float, hi: float) -> np.ndarray:
        return np.array([ms for t, ms in lat[k] if lo <= t < hi] or [float("nan")])

    status, control = (window(k, t_burst, t_end) for k in ("status", "control"))
    base = window("status", t_burst - baseline_s, t_burst)
    ok_s = [s for code, _, s in answers if code == 200]
    return {
        "kind": kind, "clients": clients, "recording_s": recording_s,
        "recording_mb": round(rec_mb, 1),
        "simulate_s": round(t_sim, 1), "answers": codes,
        "retry_after_on_every_429": bool(retry) and all(r is not None and int(r) >= 1
                                                        for r in retry),
        "retry_after_s": sorted({int(r) for r in retry if r is not None}),
        "burst_s": round(burst_s, 2), "work_s_max": round(max(ok_s), 2) if ok_s else None,
        "baseline_status_p50_ms": float(np.percentile(base, 50)),
        "baseline_status_p99_ms": float(np.percentile(base, 99)),
        "baseline_status_max_ms": float(base.max()),
        "status_requests": int(status.size), "status_p50_ms": float(np.percentile(status, 50)),
        "status_p99_ms": float(np.percentile(status, 99)), "status_max_ms": float(status.max()),
        "control_requests": int(control.size),
        "control_p99_ms": float(np.percentile(control, 99)),
        "control_max_ms": float(control.max()),
        "rss_idle_mb": round(rss_idle, 1), "rss_peak_mb": round(rss_peak, 1),
        "rss_above_idle_mb": round(rss_peak - rss_idle, 1), "limits": limits,
    }


def report(res: dict[str, Any]) -> str:
    """One line of the figures."""
    return (f"{res['clients']} concurrent {res['kind']} requests ({res['recording_s']:g}-s "
            f"recording): answers {res['answers']}, Retry-After on every 429 "
            f"{res['retry_after_on_every_429']}; /api/status before the burst p50 "
            f"{res['baseline_status_p50_ms']:.1f} p99 {res['baseline_status_p99_ms']:.1f} ms, "
            f"during: p50 {res['status_p50_ms']:.1f} ms "
            f"p99 {res['status_p99_ms']:.1f} ms max {res['status_max_ms']:.1f} ms "
            f"({res['status_requests']} polls); control p99 {res['control_p99_ms']:.1f} ms "
            f"max {res['control_max_ms']:.1f} ms; RSS idle {res['rss_idle_mb']:.0f} MiB, "
            f"+{res['rss_above_idle_mb']:.0f} MiB at peak; burst {res['burst_s']:.1f} s")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--kind", choices=sorted(PATHS), default="report")
    p.add_argument("--clients", type=int, default=100)
    p.add_argument("--recording-s", type=float, default=600.0)
    p.add_argument("--recording", type=Path, help="an existing .rdrlog instead of simulating")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    res = bench_expensive(a.kind, a.clients, a.recording_s, recording=a.recording)
    print(json.dumps(res, indent=2) if a.json else report(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
