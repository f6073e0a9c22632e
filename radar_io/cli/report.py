"""``radar-io report``: a recording → a flight report (self-contained HTML or PDF)."""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

from radar_io.errors import ConfigError


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("report", help="flight report of a recording (HTML or PDF)",
                       description="Decode a .rdrlog recording (or raw capture) and write a "
                       "flight report: plan view, height, DY/DZ, SR/EL/AZ and servo errors, "
                       "link health, air data; summary and sync-event tables.")
    p.add_argument("recording", metavar="RECORDING", help=".rdrlog recording or raw capture")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="report.html or report.pdf (format from the extension)")
    p.add_argument("--format", choices=("html", "pdf"), help="override OUT's extension")
    p.add_argument("--site", metavar="SITE", help="site TOML or packaged site name (e.g. demo)")
    p.add_argument("--path", metavar="PATH", help="reference path TOML (adds the DY/DZ chart)")
    p.add_argument("--calibration", metavar="CAL", help="calibration set JSON (radar biases)")
    p.add_argument("--airdata", metavar="CAN_LOG", help="airborne CAN log: PA − radar height")
    p.add_argument("--spec", metavar="SPEC", help="frame spec TOML")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress or summary on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.analysis.report import report_format, write_report
    from radar_io.cli.progress import Progress
    from radar_io.coordinates.reference_path import load_path
    from radar_io.coordinates.transforms import load_site
    from radar_io.decoding.biases import load_calibration
    from radar_io.wirespec.frame import load_spec

    fmt = report_format(args.output, args.format)
    if not os.path.isfile(args.recording):
        raise ConfigError(f"recording not found: {args.recording}")
    if args.airdata and not os.path.isfile(args.airdata):
        raise ConfigError(f"--airdata: CAN log not found: {args.airdata}")
    site = load_site(args.site) if args.site else None
    cal = load_calibration(args.calibration) if args.calibration else None
    ref = load_path(args.path) if args.path else None
    spec = load_spec(args.spec) if args.spec else None
    progress = Progress("report", enabled=not args.quiet)

    def prog(done: int, total: int) -> None:
        progress.total = total
        progress.update(done, "decoding")

    t0 = time.perf_counter()
    info = write_report(args.recording, args.output, fmt, site=site, calibration=cal,
                        ref_path=ref, airdata=args.airdata, spec=spec, progress=prog)
    el = time.perf_counter() - t0
    pages = f", {info['pages']} pages" if "pages" in info else ""
    progress.close(f"{args.output}: {info['frames']} frames, {info['duration_s']:.1f} s, "
                   f"{info['figures']} figures{pages}, {el:.2f} s")
    return 0


