"""The ``radar-io`` command line: one module per command, dispatched by :func:`main`."""

from radar_io.cli.main import main

__all__ = ["main"]
