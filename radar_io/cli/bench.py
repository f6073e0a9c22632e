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
    p.add_argument("--fanout-clients", type=int, default=0, metavar="N",
                   help="also run N websocket clients (batch=1, or see --fanout-per-message) on "
                   "a 1 kHz serve for 10 s: /api/status latency, messages per client, lost, "
                   "RSS; 0 to skip")
    p.add_argument("--fanout-per-message", action="store_true",
                   help="the fan-out clients take one message per websocket frame (no batch=1)")
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
    if args.fanout_clients > 0:
        from radar_io.benchmarks.service_load import bench_fanout

        fan = result["fanout"] = bench_fanout(args.fanout_clients,
                                              batch=not args.fanout_per_message)
        lines.append(f"fan-out {args.fanout_clients} clients: " + ", ".join(
            f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
            for k, v in fan.items() if not isinstance(v, (dict, list))))
    try:
        print(json.dumps(result, indent=2) if args.json else "\n".join(lines), flush=True)
    except BrokenPipeError:  # `radar-io bench --json | head`: the reader left, stop quietly
        sys.stderr.close()
    return 0
