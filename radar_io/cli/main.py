"""The ``radar-io`` command line: :data:`COMMANDS` lists one module per sub-command.

Each module has ``add_subparser(subparsers)``, which registers its parser and sets
``func`` to its ``run(args)``. A :class:`~radar_io.errors.RadarIOError` is printed as one
line and exits with code 2.
"""

from __future__ import annotations

import importlib
import sys

from radar_io.cli.common import Parser
from radar_io.errors import RadarIOError

#: one module per command, in the order ``radar-io --help`` lists them
COMMANDS = (
    "radar_io.cli.decode", "radar_io.cli.simulate", "radar_io.cli.monitor",
    "radar_io.cli.serve", "radar_io.cli.bench", "radar_io.cli.calibrate",
    "radar_io.cli.runway", "radar_io.cli.airborne", "radar_io.cli.archive",
    "radar_io.cli.report", "radar_io.cli.export", "radar_io.cli.doctor", "radar_io.cli.track",
    "radar_io.cli.annotate", "radar_io.cli.token",
)


def build_parser() -> Parser:
    parser = Parser(prog="radar-io", description="Ground tracking radar interface for flight "
                    "test: decode, record, simulate, serve and calibrate.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(name).add_subparser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except RadarIOError as exc:
        from radar_io.textfiles import one_line

        print(f"radar-io: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
