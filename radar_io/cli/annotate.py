"""``radar-io annotate``: add an annotation (test point, note, marker) to a recording after
the flight, appended to its events file (fsynced)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("annotate", help="add a test point, note or marker to a recording",
                       description="Append an annotation to REC.events.jsonl (beside "
                       "REC.rdrlog), where the report, the archive and the Chapter 10 export "
                       "read it.")
    p.add_argument("recording", metavar="REC.rdrlog")
    p.add_argument("--kind", default="marker",
                   choices=("note", "test_point_start", "test_point_end", "marker"))
    p.add_argument("--label", default="", help="e.g. TP4")
    p.add_argument("--text", default="")
    p.add_argument("--t-ns", type=int, required=True,
                   help="wall-clock time, ns since the epoch (as the recording's t_ns)")
    p.add_argument("--actor", default=os.environ.get("USER", "cli"), help="who (default $USER)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.errors import StorageError, ValidationError
    from radar_io.recording.rdrlog import RecordingReader
    from radar_io.service.routers.annotations import annotation_event

    rec = Path(args.recording)
    if rec.suffix != ".rdrlog":
        raise ValidationError(f"{rec}: expected a .rdrlog recording")
    mono = None
    with RecordingReader(rec) as reader:  # the monotonic time of t_ns from the chunk before
        for chunk in reader.chunks():
            if mono is None or chunk.t_ns <= args.t_ns:
                mono = chunk.mono_ns + (args.t_ns - chunk.t_ns)
            else:
                break
    ev = {"kind": "annotation", "t_ns": args.t_ns,
          "mono_ns": mono if mono is not None else args.t_ns,
          **annotation_event(args.kind, args.label, args.text, args.actor),
          "added_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    path = rec.with_suffix(".events.jsonl")
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        try:
            os.write(fd, (json.dumps(ev) + "\n").encode())
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as exc:
        raise StorageError(f"cannot write {path}: {exc.strerror}", errno=exc.errno) from exc
    print(ev["id"])
    print(f"annotation {ev['id']} ({args.kind} {args.label!r}) added to {path}", file=sys.stderr)
    return 0
