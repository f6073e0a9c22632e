"""``radar-io track``: a raw capture or a recording → best estimate of trajectory (BET)."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from radar_io.cli.argtypes import positive_float
from radar_io.cli.common import add_common, load_common
from radar_io.errors import ConfigError

#: bytes read and decoded at a time
CHUNK_BYTES = 1 << 22


def add_subparser(sub: Any) -> None:
    from radar_io.tracking.tracker import MODELS

    p = sub.add_parser("track", help="smoothed trajectory with velocities and covariances "
                       "(EKF + RTS smoother) to CSV, JSON lines, Parquet or Arrow",
                       description="Decode a raw capture or .rdrlog and estimate the trajectory: "
                       "an extended Kalman filter with a constant-velocity model and NIS gating, "
                       "then a Rauch-Tung-Striebel smoother; one row per accepted frame "
                       "(docs/tracking.md). Noise defaults: the site file, else the radar's "
                       "specification (5 m, 0.2 mil rms).")
    p.add_argument("input", metavar="INPUT", help="raw capture or .rdrlog")
    p.add_argument("-o", "--output", metavar="OUT", required=True,
                   help="output table (.parquet, .arrow, .csv, .jsonl)")
    p.add_argument("--format", choices=("csv", "jsonl", "parquet", "arrow"),
                   help="default from OUT's extension")
    p.add_argument("--path", metavar="PATH", help="reference path TOML: adds dy_m,dz_m,along_m,leg")
    p.add_argument("--model", choices=MODELS, default="cv",
                   help="motion model (cv: constant velocity, white-noise acceleration)")
    p.add_argument("--q-mps2", type=positive_float, metavar="Q",
                   help="acceleration noise spectral density per axis, m²/s³ (default 0.5)")
    p.add_argument("--sigma-range-m", type=positive_float, metavar="S",
                   help="range noise 1σ (m; default: site file, else 5)")
    p.add_argument("--sigma-angle-deg", type=positive_float, metavar="A",
                   help="angle noise 1σ (deg; default: site file, else 0.01125 = 0.2 mil)")
    p.add_argument("--gate-nis", type=positive_float, metavar="G",
                   help="NIS above G flags an outlier (default 30: χ²₃ false alarm 1.4e-6)")
    p.add_argument("--max-gap-s", type=positive_float, metavar="S",
                   help="no measurement used for longer ends the track (default 5)")
    p.add_argument("--forward-only", action="store_true",
                   help="the forward filter only (causal, streaming; no smoother)")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on stderr")
    add_common(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import ReadReport, iter_payloads
    from radar_io.sinks import open_table
    from radar_io.sinks.arrow_convert import output_metadata
    from radar_io.tracking.tracker import TrackParams, TrackSummary, iter_track, params_metadata

    common = load_common(args)
    path = None
    if args.path:
        from radar_io.coordinates.reference_path import load_path

        path = load_path(args.path)
    params = TrackParams.for_site(common["site"], q_mps2=args.q_mps2, model=args.model,
                                  sigma_range_m=args.sigma_range_m,
                                  sigma_angle_deg=args.sigma_angle_deg, gate_nis=args.gate_nis,
                                  max_gap_s=args.max_gap_s)
    if not os.path.isfile(args.input):
        raise ConfigError(f"input not found: {args.input}")
    meta = output_metadata(common["spec"], common["site"], common["calibration"],
                           source=args.input, **params_metadata(params, not args.forward_only))
    report = ReadReport()
    summary = TrackSummary()
    batches = iter_decode(iter_payloads(args.input, chunk_bytes=CHUNK_BYTES, report=report),
                          **common)
    writer = open_table(args.output, args.format, metadata=meta)
    try:
        stats: dict[str, int] = {}
        for out in iter_track(batches, params, smooth=not args.forward_only,
                              site=common["site"], path=path, summary=summary):
            if not writer.rows and not args.forward_only:  # smoothed: counts known already
                writer.metadata.update(summary.metadata())
            writer.write(out)
            stats = out.stats
        writer.final_metadata.update(summary.metadata())
        writer.final_metadata.update({k: str(v) for k, v in stats.items()})
        writer.close()
    except BaseException:
        writer.abort()  # no half-written output left behind
        raise
    for problem in report.problems:
        print(f"radar-io track: warning: {args.input}: {problem}", file=sys.stderr)
    if not args.quiet:
        m = summary.metadata()
        print(f"radar-io track: {summary.rows} rows, {summary.measurements} measurements, "
              f"{summary.used} used, {summary.outliers} outliers, {summary.tracks} track(s), "
              f"NIS mean {m['tracking.nis_mean']} (3 expected)", file=sys.stderr)
    return 0
