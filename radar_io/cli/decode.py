"""``radar-io decode``: a raw capture or a recording → one row per accepted frame."""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
from typing import Any

from radar_io.cli.common import add_common, load_common
from radar_io.errors import ConfigError

#: bytes read and decoded at a time (~44 k frames): memory does not grow with the input
CHUNK_BYTES = 1 << 20


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("decode", help="decode a raw capture or .rdrlog to CSV, JSON lines, "
                       "Parquet, Arrow, ASTERIX CAT048 or IRIG 106 Chapter 10",
                       description="Decode RDR1 frames from a raw capture (any bytes) or a "
                       ".rdrlog recording; one row per accepted frame. The output is written "
                       "under a temporary name and renamed when complete.")
    p.add_argument("input", metavar="INPUT", help="raw capture or .rdrlog ('-' for stdin)")
    p.add_argument("-o", "--output", metavar="OUT", help="output file (default stdout)")
    p.add_argument("--format", choices=("csv", "jsonl", "parquet", "arrow", "ast", "ch10"),
                   help="default from OUT's extension (.csv .jsonl .parquet .arrow .ast .ch10), "
                   "else csv; ast = ASTERIX CAT048 data blocks (SAC/SIC from --site); ch10 = "
                   "IRIG 106 Chapter 10 of a .rdrlog's received bytes, as `radar-io export`")
    p.add_argument("--stats", metavar="STATS.json", help="write the framer counters here")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--path", metavar="PATH", help="reference path TOML: adds dy_m,dz_m,along_m,leg")
    p.add_argument("--tlm-out", metavar="FILE", help="one TLM1 uplink frame per valid sample "
                   "(needs --path and --site for the default channels)")
    p.add_argument("--da-out", metavar="FILE", help="the 8 D/A recorder words per sample "
                   "(big-endian u16; needs --path)")
    add_common(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.cli.progress import Progress
    from radar_io.coordinates.reference_path import add_deviation
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import ReadReport, iter_payloads
    from radar_io.sinks import open_table
    from radar_io.sinks.arrow_convert import output_metadata
    from radar_io.sinks.asterix import AsterixFileWriter
    from radar_io.sinks.table import TableWriter

    common = load_common(args)
    kind = args.format or _extension_kind(args.output)
    if kind == "ch10":  # the received chunks with their times, not decoded rows
        from radar_io.cli.export import export

        if not args.output:
            raise ConfigError("a Chapter 10 output needs -o OUT.ch10 (a file, not stdout)")
        return export(args.input, args.output, spec=common["spec"], quiet=args.quiet)
    path, tlm, da = _guidance_outputs(args)  # bad options fail before any output is created
    if args.input != "-" and not os.path.exists(args.input):
        raise ConfigError(f"input not found: {args.input}")
    meta = output_metadata(common["spec"], common["site"], common["calibration"],
                           source=args.input)
    progress = Progress("decode", enabled=not args.quiet)
    report = ReadReport()
    state: dict[str, Any] = {"frames": 0}
    if args.input == "-":
        stdin = sys.stdin.buffer
        # read1: what has arrived (up to 1 MiB), so a live pipe is decoded as it comes
        read = stdin.read1 if isinstance(stdin, io.BufferedReader) else stdin.read
        chunks = iter(lambda: read(1 << 20), b"")
    else:
        chunks = iter_payloads(args.input, chunk_bytes=CHUNK_BYTES,
                               progress=lambda d, t: _progress(progress, d, t, state),
                               report=report)
    writer: TableWriter | AsterixFileWriter
    if kind == "ast":
        writer = AsterixFileWriter(args.output or "-", site=common["site"])
        writer.open()
    else:
        writer = open_table(args.output or "-", args.format, metadata=meta)
    stats: dict[str, int] = {}
    old_term = _terminate_as_interrupt()
    try:
        for batch in iter_decode(chunks, **common):
            if path is not None:
                batch = add_deviation(batch, path)
            writer.write(batch)
            if tlm is not None:
                tlm.send(batch)
            if da is not None:
                da.send(batch)
            state["frames"] = batch.stats["frames"]
            stats = batch.stats
        writer.final_metadata.update({k: str(v) for k, v in stats.items()})
        writer.close()  # the output appears under its name only now
    except BrokenPipeError:
        writer.abort()
        sys.stderr.close()  # downstream closed (e.g. `| head`): stop quietly
        return 0
    except BaseException:
        writer.abort()  # error, Ctrl-C or SIGTERM: no half-written output left behind
        raise
    finally:
        _restore_terminate(old_term)
        for sink in (tlm, da):
            if sink is not None:
                sink.close()
    for name, sink in (("tlm-out", tlm), ("da-out", da)):
        if sink is not None and not args.quiet:
            enc = sink.encoder
            sat = {k: v for k, v in enc.saturation.items() if v}
            print(f"radar-io decode: {name}: {enc.frames if name == 'tlm-out' else enc.samples} "
                  f"records, saturated {sat or 'none'}", file=sys.stderr)
    for problem in report.problems:
        print(f"radar-io decode: warning: {args.input}: {problem}", file=sys.stderr)
    progress.close(", ".join(f"{k} {v}" for k, v in stats.items()))
    if args.stats:
        doc = {**stats, "recording": {
            "corrupt_chunks": report.corrupt_chunks, "skipped_bytes": report.skipped_bytes,
            "torn_tail_bytes": report.torn_tail_bytes}} if report.chunks else stats
        try:
            with open(args.stats, "w", encoding="utf-8") as f:
                json.dump(doc, f, indent=2)
                f.write("\n")
        except OSError as exc:
            raise ConfigError(f"cannot write {args.stats}: {exc.strerror}") from exc
    return 0


def _extension_kind(output: str | None) -> str | None:
    """The non-table sink kind an output file's extension names (.ast, .ch10), if any."""
    from radar_io.sinks import SINKS

    ext = os.path.splitext(output or "")[1].lower().lstrip(".")
    return ext if ext in ("ast", "ch10") and ext in SINKS else None


def _terminate_as_interrupt() -> Any:
    """Make SIGTERM raise KeyboardInterrupt (as Ctrl-C does), so outputs are cleaned up."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def _raise(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    return signal.signal(signal.SIGTERM, _raise)


def _restore_terminate(old: Any) -> None:
    import signal

    if old is not None:
        signal.signal(signal.SIGTERM, old)


def _guidance_outputs(args: argparse.Namespace) -> tuple[Any, Any, Any]:
    """The reference path and the TLM1 / D/A file sinks asked for on the command line."""
    path = tlm = da = None
    if args.path:
        from radar_io.coordinates.reference_path import load_path

        path = load_path(args.path)
    if args.tlm_out or args.da_out:
        from radar_io.sinks import open_sink

        tlm = open_sink("tlm1", args.tlm_out) if args.tlm_out else None
        da = open_sink("da", args.da_out) if args.da_out else None
    return path, tlm, da


def _progress(progress: Any, done: int, total: int, state: dict[str, Any]) -> None:
    progress.total = total
    progress.update(done, f"{state['frames']} frames")
