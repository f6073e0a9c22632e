"""``radar-io bench``: throughput and latency figures, anchors measured in the same run."""

from __future__ import annotations

import argparse
import json
from typing import Any

def add_subparser(sub: Any) -> None:
    p = sub.add_parser("bench", help="throughput benchmarks",
                       description="Frames/s of the per-frame and batch paths and a memcpy "
                       "reference, measured in the same run.")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--frames", type=int, default=2_000_000, help="frames in the batch test stream")
    p.add_argument("--repeat", type=int, default=5, help="best of N runs")
    p.add_argument("--serve-seconds", type=float, default=5.0,
                   help="length of the live-service latency run: 1 kHz frames written into a "
                   "pty, 20 websocket clients (one never reading); 0 to skip")
    p.add_argument("--core-only", action="store_true",
                   help="only the decoding paths (no service latency, no plug-in benchmarks)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.benchmarks.core import run_bench

    result = run_bench(frames=args.frames, repeat=args.repeat, include_plugins=not args.core_only,
                       serve_seconds=0.0 if args.core_only else args.serve_seconds)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k:45s} {v:,.1f}" if isinstance(v, float) else f"{k:45s} {v}")
    return 0
