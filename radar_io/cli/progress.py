"""Progress of long work on stderr."""

from __future__ import annotations

import sys
import time
from typing import IO


class Progress:
    """A progress line on stderr: refreshed in place on a terminal, every few seconds otherwise."""

    def __init__(self, label: str, total: int | None = None, stream: IO[str] | None = None,
                 enabled: bool = True, interval_s: float | None = None) -> None:
        self.label, self.total = label, total
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.enabled = enabled
        self.interval_s = interval_s if interval_s is not None else (0.2 if self.tty else 5.0)
        self.t0 = time.monotonic()
        self._last = 0.0
        self._shown = False

    def update(self, done: int, extra: str = "", force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < self.interval_s:
            return
        self._last = now
        el = now - self.t0
        if self.total:
            pct = 100.0 * done / self.total
            rate = done / el if el > 0 else 0.0
            eta = (self.total - done) / rate if rate > 0 else float("nan")
            msg = (f"{self.label}: {done / 1e6:8.1f} / {self.total / 1e6:.1f} MB ({pct:5.1f} %)"
                   f"  {el:6.1f} s  eta {eta:5.0f} s  {extra}")
        else:
            msg = f"{self.label}: {done / 1e6:8.1f} MB  {el:6.1f} s  {extra}"
        if self.tty:
            self.stream.write("\r" + msg.ljust(100)[:120])
        else:
            self.stream.write(msg + "\n")
        self.stream.flush()
        self._shown = True

    def close(self, summary: str = "") -> None:
        if not self.enabled:
            return
        if self.tty and self._shown:
            self.stream.write("\n")
        if summary:
            self.stream.write(f"{self.label}: {summary}\n")
        self.stream.flush()
