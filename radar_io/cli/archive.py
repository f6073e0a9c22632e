"""``radar-io archive``: recordings → a Hive-partitioned Parquet dataset for DuckDB / Spark."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from radar_io.cli.common import add_common, load_common


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("archive", help="archive recordings as a partitioned Parquet dataset",
                       description="Decode recordings (files, or the .rdrlog files under "
                       "directories) into OUT/site=…/date=…/recording=…/part-0.parquet. "
                       "Recordings already archived with the same content are skipped.")
    p.add_argument("inputs", nargs="+", metavar="RECORDING_OR_DIR")
    p.add_argument("--out", required=True, metavar="DIR", help="archive root directory")
    p.add_argument("--site-name", metavar="NAME",
                   help="partition site name (default: --site's name, else the recording's)")
    p.add_argument("--path", metavar="PATH", help="reference path TOML: adds dy_m,dz_m,along_m,leg")
    p.add_argument("--force", action="store_true", help="rewrite files already up to date")
    p.add_argument("-q", "--quiet", action="store_true", help="no line per recording")
    add_common(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.analysis.archive import archive

    common = load_common(args)
    ref = None
    if args.path:
        from radar_io.coordinates.reference_path import load_path

        ref = load_path(args.path)
    site = common["site"] if common["site"] is not None else args.site_name
    if common["site"] is not None and args.site_name:
        from dataclasses import replace

        site = replace(common["site"], name=args.site_name)
    written = skipped = 0
    for res in archive(args.inputs, args.out, site=site, spec=common["spec"],
                       calibration=common["calibration"], reference_path=ref, force=args.force):
        for problem in res.problems:
            print(f"radar-io archive: warning: {res.source}: {problem}", file=sys.stderr)
        if res.written:
            written += 1
        else:
            skipped += 1
        if not args.quiet:
            what = "written" if res.written else "up to date"
            counts = ", ".join(f"{k} {v}" for k, v in res.stats.items())
            print(f"{res.path}: {what}: {counts}", file=sys.stderr)
    if not args.quiet:
        print(f"radar-io archive: {written} written, {skipped} up to date", file=sys.stderr)
    return 0
