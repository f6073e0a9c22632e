"""Progress of long work on stderr — only when stderr is a terminal.

On a terminal one line is refreshed in place (carriage return); written to a log
file or a pipe, nothing is printed while working (no carriage-return noise), and
:meth:`Progress.close` prints its one-line summary either way. Every command uses
this class for its progress.
"""

from __future__ import annotations

import sys
import time
from typing import IO


class Progress:
    """A progress line on stderr, refreshed in place; silent unless the stream is a TTY."""

    def __init__(self, label: str, total: int | None = None, stream: IO[str] | None = None,
                 enabled: bool = True, interval_s: float = 0.2, unit: str = "MB",
                 scale: float = 1e-6) -> None:
        self.label, self.total = label, total
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.quiet = not enabled          #: -q: no summary either
        self.enabled = enabled and self.tty
        self.interval_s = interval_s
        self.unit, self.scale = unit, scale
        self.t0 = time.monotonic()
        self._last = 0.0
        self._shown = False

    def update(self, done: float, extra: str = "", force: bool = False) -> None:
        """Show ``done`` (of :attr:`total`) units of work; rate-limited to ``interval_s``."""
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < self.interval_s:
            return
        self._last = now
        el = now - self.t0
        s, u = self.scale, self.unit
        fmt = "8.0f" if s == 1.0 else "8.1f"
        if self.total:
            pct = 100.0 * done / self.total
            rate = done / el if el > 0 else 0.0
            eta = (self.total - done) / rate if rate > 0 else float("nan")
            msg = (f"{self.label}: {done * s:{fmt}} / {self.total * s:.{0 if s == 1.0 else 1}f} {u}"
                   f" ({pct:5.1f} %)  {el:6.1f} s  eta {eta:5.0f} s  {extra}")
        else:
            msg = f"{self.label}: {done * s:{fmt}} {u}  {el:6.1f} s  {extra}"
        self.stream.write("\r" + msg.ljust(100)[:120])
        self.stream.flush()
        self._shown = True

    def close(self, summary: str = "") -> None:
        """End the in-place line (TTY) and print ``summary`` (unless quiet)."""
        if self._shown:
            self.stream.write("\n")
            self._shown = False
        if summary and not self.quiet:
            self.stream.write(f"{self.label}: {summary}\n")
        self.stream.flush()
