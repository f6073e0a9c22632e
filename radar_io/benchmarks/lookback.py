"""Look-back benchmark: series queries over a long recording on a real service, over HTTP.

``python -m radar_io.benchmarks.lookback [--hours 1] [--queries 50] [--points 1000]
[--workdir DIR]`` (also ``radar-io bench --lookback-hours H``)

1. Simulates an ``--hours`` recording at 1 kHz (``radar-io simulate``, as the output
   benchmark does) into ``DIR/data/recordings/``.
2. Starts ``radar-io serve --port 0`` on ``sim://`` (demo site: runway and geodetic
   columns) with the demo reference path (deviation columns), recording manual (no other
   recording is made).
3. Reads the service's RSS, times the first ``GET /api/recordings/ID/series?columns=h_m,dy_m
   &points=P`` (it builds the index), then ``--queries`` ranges chosen at random: width
   log-uniform from the whole recording down to 10 ms, start uniform; RSS again.
4. Checks every answer: at most ``points`` buckets (2 × ``points`` values per column), and
   the values equal numpy min / max over the same buckets of ``decode_bytes`` of the whole
   recording (with the path deviation), each frame timed by the batch framer fed chunk by
   chunk (the live path's rule).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

#: the reference path of the benchmark (demo site, radar frame)
PATH_NAME = "demo_track_radar.toml"
COLUMNS = ("h_m", "dy_m")


def _get(base: str, path: str) -> tuple[float, float, dict[str, Any]]:
    """(seconds, the server's CPU seconds from its Server-Timing header, JSON body) of one
    GET, timed on the monotonic clock."""
    t = time.perf_counter()
    with urllib.request.urlopen(base + path, timeout=600) as r:
        body = r.read()
        timing = r.headers.get("Server-Timing", "")
    wall = time.perf_counter() - t
    cpu = next((float(part.split("dur=")[1]) / 1e3 for part in timing.split(",")
                if part.strip().startswith("cpu;")), float("nan"))
    return wall, cpu, json.loads(body)


def reference_columns(rec: Path, path_file: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Each frame's time (batch framer fed chunk by chunk) and the benchmark's columns from
    ``decode_bytes`` of the whole recording with the demo site and the path deviation."""
    from radar_io.coordinates.reference_path import add_deviation, load_path
    from radar_io.coordinates.transforms import load_site
    from radar_io.decoding.batch_decoder import decode_bytes
    from radar_io.framing.core import BatchFramer
    from radar_io.recording.rdrlog import RecordingReader

    framer = BatchFramer()
    times: list[np.ndarray] = []
    payloads: list[bytes] = []
    t0: int | None = None
    with RecordingReader(rec) as r:
        for c in r:
            t0 = c.mono_ns if t0 is None else t0
            payloads.append(c.data)
            n = sum(b.shape[0] for b in framer.feed_blocks(c.data))
            if n:
                times.append(np.full(n, (c.mono_ns - t0) / 1e9))
    t = np.maximum.accumulate(np.concatenate(times))
    batch = add_deviation(decode_bytes(b"".join(payloads), site=load_site("demo")),
                          load_path(path_file))
    if len(batch) != t.size:
        raise AssertionError(f"decode_bytes: {len(batch)} frames, the framer {t.size}")
    return t, {c: np.array(batch[c], dtype=np.float64) for c in COLUMNS}


def expected(t: np.ndarray, col: np.ndarray, start_s: float, end_s: float, points: int
             ) -> tuple[list[float], np.ndarray, np.ndarray, bool]:
    """Bucket starts, min, max (NaN: none) and whether decimated, by plain numpy."""
    i0, i1 = np.searchsorted(t, start_s, "left"), np.searchsorted(t, end_s, "right")
    if i1 - i0 <= points:
        return t[i0:i1].tolist(), col[i0:i1], col[i0:i1], False
    edges = np.minimum(start_s + np.arange(points) * ((end_s - start_s) / points), end_s)
    rows = np.append(np.searchsorted(t, edges, "left"), i1)
    mn, mx = np.full(points, np.nan), np.full(points, np.nan)
    for k in range(points):
        v = col[rows[k]:rows[k + 1]]
        if v.size:
            with np.errstate(invalid="ignore"):
                mn[k], mx[k] = np.fmin.reduce(v), np.fmax.reduce(v)
    return edges.tolist(), mn, mx, True


def _same(got: list[float | None], want: np.ndarray) -> bool:
    return np.array_equal(np.array([np.nan if v is None else v for v in got], dtype=np.float64),
                          want, equal_nan=True)


def run(hours: float = 1.0, queries: int = 50, points: int = 1000, seed: int = 19,
        workdir: str | None = None) -> dict[str, Any]:
    from radar_io.benchmarks.outputs import make_recording
    from radar_io.benchmarks.service_load import ServeProcess, rss_mb
    from radar_io.wirespec.frame import spec_dir

    tmp = Path(workdir or tempfile.mkdtemp(prefix="radar-io-bench-lookback-"))
    recs = tmp / "data" / "recordings"
    recs.mkdir(parents=True, exist_ok=True)
    rec = recs / "hour.rdrlog"
    res: dict[str, Any] = {"hours": hours, "points": points, "queries": queries}
    path_file = spec_dir() / "paths" / PATH_NAME
    try:
        if not rec.exists():
            res["simulate_s"] = make_recording(rec, hours)
        shutil.rmtree(rec.with_suffix(".series"), ignore_errors=True)  # the first query builds
        res["recording_mb"] = rec.stat().st_size / 1e6
        cfg = tmp / "serve.toml"
        cfg.write_text(f'auto_record = "manual"\npath = "{path_file}"\n')
        answers: list[tuple[float, float, dict[str, Any]]] = []
        with ServeProcess("sim://", tmp / "data", extra=("--config", str(cfg))) as srv:
            pid = srv.proc.pid
            res["rss_before_mb"] = rss_mb(pid)
            res["load_before"] = os.getloadavg()[0]
            url = f"/api/recordings/hour/series?columns={','.join(COLUMNS)}&points={points}"
            res["first_query_s"], res["first_query_cpu_s"], first = _get(srv.base, url)
            duration = first["end_s"]
            answers.append((0.0, duration, first))
            rng = np.random.default_rng(seed)
            times, cpus = [], []
            for _ in range(queries):
                width = float(10 ** rng.uniform(np.log10(0.01), np.log10(duration)))
                start = float(rng.uniform(0.0, duration - width))
                s, cpu, body = _get(srv.base, f"{url}&start_s={start!r}&end_s={start + width!r}")
                times.append(s)
                cpus.append(cpu)
                answers.append((start, start + width, body))
            res["rss_after_mb"] = rss_mb(pid)
            res["load_after"] = os.getloadavg()[0]
        man = json.loads((rec.with_suffix(".series") / "manifest.json").read_text())
        res["frames"] = man["rows"]
        res["index_mb"] = sum(p.stat().st_size for p in rec.with_suffix(".series").iterdir()) / 1e6
        res["build_s"] = man["build_s"]
        for key, values in (("query_ms", times), ("query_cpu_ms", cpus)):
            q = np.array(values) * 1e3
            res[key] = {"p50": float(np.percentile(q, 50)), "p95": float(np.percentile(q, 95)),
                        "max": float(q.max())}
        res["decimated"] = sum(1 for _, _, b in answers if b["decimated"])
        res["max_values_per_column"] = max(len(b["columns"][c]["min"]) + len(b["columns"][c]["max"])
                                           for _, _, b in answers for c in COLUMNS)
        t, cols = reference_columns(rec, path_file)
        equal = 0
        for _, _, b in answers:
            ok = True
            for c in COLUMNS:
                t_s, mn, mx, dec = expected(t, cols[c], b["start_s"], b["end_s"], points)
                ok &= (dec == b["decimated"] and t_s == b["t_s"]
                       and _same(b["columns"][c]["min"], mn) and _same(b["columns"][c]["max"], mx))
            equal += ok
        res["answers_equal"] = equal
        res["answers"] = len(answers)
    finally:
        if workdir is None:
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            shutil.rmtree(rec.with_suffix(".series"), ignore_errors=True)
    return res


def report(res: dict[str, Any]) -> str:
    b = res["build_s"]
    q, c = res["query_ms"], res["query_cpu_ms"]
    return (
        f"look-back: {res['hours']} h recording ({res['frames']:,} frames, "
        f"{res['recording_mb']:.0f} MB; index {res['index_mb']:.0f} MB), columns "
        f"{','.join(COLUMNS)}, points={res['points']}, over HTTP; load average "
        f"{res['load_before']:.1f} before, {res['load_after']:.1f} after\n"
        f"  first query (index build) {res['first_query_s']:.2f} s wall (goal <= 10 s), "
        f"{res['first_query_cpu_s']:.2f} s CPU: build {b['total']:.2f} s = read "
        f"{b['read']:.2f} + frame {b['frame']:.2f} + decode {b['decode']:.2f} + "
        f"deviation/events {b['deviation']:.2f} + write/pyramid {b['write']:.2f} s\n"
        f"  {res['queries']} random ranges 10 ms .. whole ({res['decimated'] - 1} decimated): "
        f"p50 {q['p50']:.1f} ms, p95 {q['p95']:.1f} ms (goal <= 100 ms), max {q['max']:.1f} ms "
        f"wall; server CPU p50 {c['p50']:.1f}, p95 {c['p95']:.1f}, max {c['max']:.1f} ms\n"
        f"  at most {res['max_values_per_column']} values per column (limit "
        f"{2 * res['points']}); {res['answers_equal']}/{res['answers']} answers equal to numpy "
        f"min/max over decode_bytes; service RSS {res['rss_before_mb']:.0f} MB before, "
        f"{res['rss_after_mb']:.0f} MB after")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m radar_io.benchmarks.lookback",
                                description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--hours", type=float, default=1.0)
    p.add_argument("--queries", type=int, default=50)
    p.add_argument("--points", type=int, default=1000)
    p.add_argument("--seed", type=int, default=19)
    p.add_argument("--workdir", help="keep the recording here (reused on the next run)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    res = run(args.hours, args.queries, args.points, args.seed, args.workdir)
    print(json.dumps(res, indent=2) if args.json else report(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
