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
    p.add_argument("--fixes", metavar="FIXES.csv",
                   help="photo fixes fused as position measurements: sync_index (0-based SYNC "
                   "0->1 edge of INPUT), photo_x_m, photo_y_m, photo_z_m (Z down), "
                   "sigma_x_m, sigma_y_m, sigma_z_m")
    p.add_argument("--estimate-bias", action="store_true",
                   help="estimate the radar biases dSR, dEL, dAZ against the fixes and track "
                   "the bias-corrected measurements")
    p.add_argument("--bias-out", metavar="CAL.json",
                   help="write the estimated biases as a calibration set (with --estimate-bias)")
    p.add_argument("--airdata", metavar="LOG",
                   help="airborne recorder CAN log (as radar-io align reads): pressure altitude "
                   "aligned by the shutter events, its offset estimated, fused as height")
    p.add_argument("--dbc", metavar="DBC", help="air-data DBC (default firmware_specs/airdata.dbc)")
    p.add_argument("--sigma-pa-m", type=positive_float, metavar="S",
                   help="pressure-altitude noise 1σ (m; default 3)")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on stderr")
    add_common(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import ReadReport, iter_payloads
    from radar_io.sinks import open_table
    from radar_io.sinks.arrow_convert import output_metadata
    from radar_io.tracking.tracker import (
        TrackParams,
        TrackSummary,
        iter_track,
        params_metadata,
    )

    common = load_common(args)
    path = None
    if args.path:
        from radar_io.coordinates.reference_path import load_path

        path = load_path(args.path)
    params = TrackParams.for_site(common["site"], q_mps2=args.q_mps2, model=args.model,
                                  sigma_range_m=args.sigma_range_m,
                                  sigma_angle_deg=args.sigma_angle_deg, gate_nis=args.gate_nis,
                                  max_gap_s=args.max_gap_s, sigma_pa_m=args.sigma_pa_m)
    if not os.path.isfile(args.input):
        raise ConfigError(f"input not found: {args.input}")
    if args.forward_only and (args.fixes or args.estimate_bias or args.airdata):
        raise ConfigError("--fixes, --airdata and --estimate-bias need the smoother "
                          "(drop --forward-only)")
    if (args.estimate_bias or args.bias_out) and not args.fixes:
        raise ConfigError("--estimate-bias and --bias-out need --fixes FIXES.csv")
    if args.bias_out and not args.estimate_bias:
        raise ConfigError("--bias-out needs --estimate-bias")
    fixes = None
    if args.fixes:
        from radar_io.tracking.fusion import read_fixes

        fixes = read_fixes(args.fixes)
    airdata = None
    if args.airdata:
        from radar_io.decoding.airdata import load_dbc, read_can_log

        airdata = read_can_log(args.airdata, load_dbc(args.dbc))
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
                              site=common["site"], path=path, summary=summary, fixes=fixes,
                              estimate_bias=args.estimate_bias, airdata=airdata):
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
    if args.bias_out:
        _write_bias(args, summary.bias, common["calibration"], fixes)
    for problem in report.problems:
        print(f"radar-io track: warning: {args.input}: {problem}", file=sys.stderr)
    if not args.quiet:
        m = summary.metadata()
        print(f"radar-io track: {summary.rows} rows, {summary.measurements} measurements, "
              f"{summary.used} used, {summary.outliers} outliers, {summary.tracks} track(s), "
              f"NIS mean {m['tracking.nis_mean']} (3 expected)", file=sys.stderr)
        if summary.bias is not None:
            print("radar-io track: bias " + ", ".join(
                f"{k} {m[f'tracking.bias_{k}']}" for k in ("dsr_m", "del_deg", "daz_deg"))
                + f" from {summary.bias.fixes_used} fixes", file=sys.stderr)
        if summary.pressure_altitude is not None:
            print(f"radar-io track: pressure altitude: {m['tracking.pa_samples']} samples, "
                  f"offset from radar height {m['tracking.pa_offset_m']} m", file=sys.stderr)
    return 0


def _write_bias(args: argparse.Namespace, bias: Any, base: Any, fixes: Any) -> None:
    """The estimate as a calibration set: biases = the input's calibration + the estimate."""
    from pathlib import Path

    from radar_io.decoding.biases import Calibration, save_calibration, utc_now_iso

    stats = bias.statistics(base)
    cal = Calibration(
        dsr_m=stats["dsr_m"]["estimate"], del_deg=stats["del_deg"]["estimate"],
        daz_deg=stats["daz_deg"]["estimate"], id=f"track-{Path(args.input).stem}",
        created_utc=utc_now_iso(), statistics=stats,
        provenance={"tool": "radar-io track --estimate-bias", "method": stats["method"],
                    "input": Path(args.input).name, "fixes": Path(args.fixes).name,
                    "fixes_sha256": fixes.sha256})
    save_calibration(cal, args.bias_out)
