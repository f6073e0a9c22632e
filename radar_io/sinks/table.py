"""Writing measurements as CSV or JSON lines."""

from __future__ import annotations

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


def jsonable(v: Any) -> Any:
    """A JSON-safe value: NaN → None, numpy scalars → Python."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and v != v:
        return None
    return v
