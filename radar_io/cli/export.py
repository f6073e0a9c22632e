"""``radar-io export``: a ``.rdrlog`` recording → an IRIG 106 Chapter 10 file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from radar_io.cli.common import load_common


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("export", help="export a .rdrlog recording to IRIG 106 Chapter 10",
                       description="Write a recording as an IRIG 106 Chapter 10 file (packet "
                       "formats of 106-17 Chapter 11): TMATS setup record, a time packet per "
                       "second, one UART message per received chunk stamped with the 10 MHz "
                       "relative time counter, recording events (GO, SYNC, clock steps, alarms "
                       "and annotations from REC.events.jsonl). Written under a temporary name "
                       "and renamed when complete. See docs/chapter10.md.")
    p.add_argument("input", metavar="REC.rdrlog", help="the recording")
    p.add_argument("-o", "--output", metavar="OUT.ch10",
                   help="output file (default: the recording's name with .ch10)")
    p.add_argument("--events", metavar="EVENTS.jsonl",
                   help="event log (default: REC.events.jsonl beside the recording, if any)")
    p.add_argument("--spec", metavar="SPEC", help="frame spec TOML (for the GO / SYNC edges)")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = args.output or str(Path(args.input).with_suffix(".ch10"))
    return export(args.input, out, events=args.events, spec=load_common(args)["spec"],
                  quiet=args.quiet)


def export(src: str, out: str, *, events: str | None = None, spec: Any = None,
           quiet: bool = False) -> int:
    """Export ``src`` to ``out`` with a progress line and a summary (shared with decode)."""
    from radar_io.cli.progress import Progress
    from radar_io.sinks.ch10 import export_recording

    progress = Progress("export", enabled=not quiet)

    def step(done: int, total: int) -> None:
        progress.total = total
        progress.update(done, "")

    res = export_recording(src, out, events_path=events, spec=spec, progress=step)
    for problem in res["problems"]:
        print(f"radar-io export: warning: {src}: {problem}", file=sys.stderr)
    if res["events_skipped"]:
        print(f"radar-io export: warning: {res['events_skipped']} event-log records without a "
              "time or a known kind skipped", file=sys.stderr)
    progress.close(f"{out}: {res['packets']} packets, {res['bytes']} bytes, "
                   f"{res['uart_messages']} UART messages ({res['chunks']} chunks), "
                   f"{res['time_packets']} time packets, events {res['events'] or 'none'}")
    return 0
