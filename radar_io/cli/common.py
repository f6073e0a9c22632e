"""What the sub-commands share: one-line argparse errors and the site / calibration /
spec options every decoding command takes."""

from __future__ import annotations

import argparse
from typing import Any, NoReturn


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump) and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def load_common(args: argparse.Namespace) -> dict[str, Any]:
    from radar_io.coordinates.transforms import load_site
    from radar_io.decoding.biases import load_calibration
    from radar_io.wirespec.frame import load_spec

    return {
        "spec": load_spec(args.spec) if getattr(args, "spec", None) else load_spec(),
        "site": load_site(args.site) if getattr(args, "site", None) else None,
        "calibration": load_calibration(args.calibration) if getattr(args, "calibration", None)
        else None,
    }


def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--site", metavar="SITE", help="site TOML file or packaged site name, e.g. demo "
                   "(adds runway and geodetic columns)")
    p.add_argument("--calibration", metavar="CAL", help="calibration set JSON (radar biases)")
    p.add_argument("--spec", metavar="SPEC", help="frame spec TOML (default firmware_specs/rdr1.toml)")
