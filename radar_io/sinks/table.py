"""Writing measurements as CSV or JSON lines, and progress lines for long jobs."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import IO, Any

import numpy as np

from radar_io.decoding.decoders import MeasurementBatch


def _column_text(a: np.ndarray, empty: str) -> list[str]:
    """Text of each value: shortest round-trip repr for floats, ``empty`` for NaN."""
    if a.dtype.kind == "f":
        return [empty if v != v else repr(v) for v in a.tolist()]
    return list(map(str, a.tolist()))


class MeasurementWriter:
    """Streams batches to a text file as CSV (header + rows) or JSONL (one object per row).

    NG samples leave the compensated and coordinate fields empty in CSV and
    ``null`` in JSONL.
    """

    def __init__(self, out: IO[str], columns: Sequence[str], fmt: str = "csv") -> None:
        if fmt not in ("csv", "jsonl"):
            raise ValueError(f"unknown format {fmt!r}")
        self.out, self.columns, self.fmt = out, tuple(columns), fmt
        self.rows = 0
        if fmt == "csv":
            out.write(",".join(self.columns) + "\n")
            self._empty = ""
        else:
            self._empty = "null"
            self._template = "{" + ",".join(f'"{c}":%s' for c in self.columns) + "}"

    #: rows formatted at a time (bounds the memory of the text being built)
    ROWS_PER_WRITE = 8192

    def write(self, batch: MeasurementBatch) -> None:
        n = len(batch)
        for s in range(0, n, self.ROWS_PER_WRITE):
            e = min(n, s + self.ROWS_PER_WRITE)
            cols = [_column_text(batch[c][s:e], self._empty) for c in self.columns]
            if self.fmt == "csv":
                text = "\n".join(map(",".join, zip(*cols)))
            else:
                tpl = self._template
                text = "\n".join(tpl % row for row in zip(*cols))
            self.out.write(text + "\n")
        self.rows += n


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


def jsonable(v: Any) -> Any:
    """A JSON-safe value: NaN → None, numpy scalars → Python."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and v != v:
        return None
    return v
