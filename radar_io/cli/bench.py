"""``radar-io bench``: decoding figures that tell the truth — the first call in a fresh process
beside the best of N, peak RSS, and anchors (plain-Python reference, memcpy) from the same run."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("bench", help="throughput benchmarks",
                       description="decode_bytes: first call in a fresh process and best of N, "
                       "peak RSS, with a plain-Python reference and a memcpy measured in the "
                       "same run (ratios); the per-frame path; the service latency.")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--frames", type=int, default=2_000_000, help="frames in the test streams")
    p.add_argument("--repeat", type=int, default=5, help="best of N warm calls")
    p.add_argument("--serve-seconds", type=float, default=5.0,
                   help="length of the live-service latency run: 1 kHz frames written into a "
                   "pty, 20 websocket clients (one never reading); 0 to skip")
    p.add_argument("--outputs-hours", type=float, default=0.0, metavar="H",
                   help="also decode an H-hour 1 kHz recording to Parquet and CSV through the "
                   "CLI beside pyarrow anchors (fresh processes, peak RSS); 0 to skip")
    p.add_argument("--lookback-hours", type=float, default=0.0, metavar="H",
                   help="also time look-back series queries on an H-hour 1 kHz recording "
                   "through a real service over HTTP: the first query (index build), then 50 "
                   "random ranges (p50 / p95 / max), answers checked against numpy; 0 to skip")
    p.add_argument("--ch10-hours", type=float, default=0.0, metavar="H",
                   help="also export an H-hour 1 kHz recording to IRIG 106 Chapter 10 in a "
                   "fresh process (wall, CPU, peak RSS); 0 to skip")
    p.add_argument("--tracking-hours", type=float, default=0.0, metavar="H",
                   help="also track an H-hour 1 kHz recording to smoothed Parquet through the "
                   "CLI (fresh processes: first with numba compiling, then cached; peak RSS) "
                   "beside Stone Soup's EKF + smoother per measurement; 0 to skip")
    p.add_argument("--tracking-live", action="store_true",
                   help="also time the live tracking filter: start cost (numba) and the "
                   "pipeline's processing per chunk with and without it")
    p.add_argument("--fanout-clients", type=int, default=0, metavar="N",
                   help="also run N websocket clients (batch=1, or see --fanout-per-message) on "
                   "a 1 kHz serve for 10 s: /api/status latency, messages per client, lost, "
                   "RSS; 0 to skip")
    p.add_argument("--fanout-per-message", action="store_true",
                   help="the fan-out clients take one message per websocket frame (no batch=1)")
    p.add_argument("--expensive-clients", type=int, default=0, metavar="N",
                   help="also fire N concurrent flight-report requests, then N/2 sync-event "
                   "queries, of one recording at a fresh serve: answers (429 + Retry-After "
                   "beyond the limit), /api/status and control latency, RSS; 0 to skip")
    p.add_argument("--expensive-recording-s", type=float, default=600.0, metavar="S",
                   help="length of the recording those requests ask for (default 600 s)")
    p.add_argument("--core-only", action="store_true",
                   help="only the decoding paths (no service latency, no plug-in benchmarks)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.benchmarks.core import run_bench, summary_lines

    result = run_bench(frames=args.frames, repeat=args.repeat, include_plugins=not args.core_only,
                       serve_seconds=0.0 if args.core_only else args.serve_seconds)
    lines = summary_lines(result)
    if args.outputs_hours > 0:
        from radar_io.benchmarks import outputs

        result["outputs"] = outputs.run(hours=args.outputs_hours, long_hours=0.0)
        lines.append(outputs.report(result["outputs"]))
    if args.lookback_hours > 0:
        from radar_io.benchmarks import lookback

        result["lookback"] = lookback.run(hours=args.lookback_hours)
        lines.append(lookback.report(result["lookback"]))
    if args.ch10_hours > 0:
        from radar_io.benchmarks import ch10

        result["ch10"] = ch10.run(minutes=0.0, hours=args.ch10_hours)
        lines.append(ch10.report(result["ch10"]))
    if args.tracking_hours > 0:
        from radar_io.benchmarks import tracking

        result["tracking"] = tracking.run(hours=args.tracking_hours)
        lines.append(tracking.report(result["tracking"]))
    if args.tracking_live:
        from radar_io.benchmarks import tracking

        result["tracking_live"] = tracking.live_cost()
        lines.append(tracking.live_report(result["tracking_live"]))
    if args.fanout_clients > 0:
        from radar_io.benchmarks.service_load import bench_fanout

        fan = result["fanout"] = bench_fanout(args.fanout_clients,
                                              batch=not args.fanout_per_message)
        lines.append(f"fan-out {args.fanout_clients} clients: " + ", ".join(
            f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
            for k, v in fan.items() if not isinstance(v, (dict, list))))
    if args.expensive_clients > 0:
        from radar_io.benchmarks import expensive

        result["expensive"] = [
            expensive.bench_expensive(kind, n, args.expensive_recording_s)
            for kind, n in (("report", args.expensive_clients),
                            ("sync", max(1, args.expensive_clients // 2)))]
        lines += [expensive.report(r) for r in result["expensive"]]
    try:
        print(json.dumps(result, indent=2) if args.json else "\n".join(lines), flush=True)
    except BrokenPipeError:  # `radar-io bench --json | head`: the reader left, stop quietly
        sys.stderr.close()
    return 0
