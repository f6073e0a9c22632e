"""``radar-io bench``: decoding figures that tell the truth — the first call in a fresh process
beside the best of N, peak RSS, and anchors (plain-Python reference, memcpy) from the same run."""

from __future__ import annotations

import argparse
import json
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
    p.add_argument("--core-only", action="store_true",
                   help="only the decoding paths (no service latency, no plug-in benchmarks)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.benchmarks.core import run_bench, summary_lines

    result = run_bench(frames=args.frames, repeat=args.repeat, include_plugins=not args.core_only,
                       serve_seconds=0.0 if args.core_only else args.serve_seconds)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print("\n".join(summary_lines(result)))
    return 0
