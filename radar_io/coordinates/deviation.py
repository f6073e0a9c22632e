"""Deviation from a reference path as a pipeline processor (radar-interface.md §6).

:class:`DeviationProcessor` adds ``dy_m`` (lateral, m), ``dz_m`` (vertical, m),
``along_m`` (distance along the path, m) and ``leg`` (index, −1 = none) to each
message of a batch, in the path's frame (radar or runway), vectorised over the batch.
"""

from __future__ import annotations

from typing import Any

from radar_io.coordinates.reference_path import DEVIATION_COLUMNS, ReferencePath
from radar_io.sinks.worker import message_columns


class DeviationProcessor:
    """Adds the path deviation to each message (None / leg -1 when there is no position)."""

    def __init__(self, path: ReferencePath) -> None:
        self.path = path

    def __call__(self, msgs: list[dict[str, Any]]) -> None:
        cols = message_columns(msgs, self.path.columns)
        if len(cols) < 3:
            for m in msgs:
                m.update(dy_m=None, dz_m=None, along_m=None, leg=-1)
            return
        dev = self.path.deviation(*(cols[c] for c in self.path.columns))
        for i, m in enumerate(msgs):
            for c in DEVIATION_COLUMNS:
                v = dev[c][i]
                m[c] = int(v) if c == "leg" else (None if v != v else float(v))
