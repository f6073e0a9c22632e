"""Deviation from a reference path as a pipeline processor (radar-interface.md §6).

:class:`DeviationProcessor` adds ``dy_m`` (lateral, m), ``dz_m`` (vertical, m),
``along_m`` (distance along the path, m) and ``leg`` (index, −1 = none) to each
message of a batch, in the path's frame (radar or runway), vectorised over the batch.
Messages that carry the live tracking filter's flight-path angle (``fpa_deg``,
``fpa_sigma_deg``) also get the path's glide-path angle at ``along_m`` (``gpa_deg``,
positive up: a descending approach is negative) and the error
``gpa_err_deg = fpa_deg − gpa_deg`` with its σ ``gpa_err_sigma_deg`` (the path is exact).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from radar_io.coordinates.reference_path import DEVIATION_COLUMNS, ReferencePath
from radar_io.sinks.worker import message_columns


class DeviationProcessor:
    """Adds the path deviation to each message (None / leg -1 when there is no position)."""

    def __init__(self, path: ReferencePath) -> None:
        self.path = path

    def __call__(self, msgs: list[dict[str, Any]]) -> None:
        cols = message_columns(msgs, self.path.columns)
        fpa = "fpa_deg" in msgs[0]
        if len(cols) < 3:
            for m in msgs:
                m.update(dy_m=None, dz_m=None, along_m=None, leg=-1)
                if fpa:
                    m.update(gpa_deg=None, gpa_err_deg=None, gpa_err_sigma_deg=None)
            return
        dev = self.path.deviation(*(cols[c] for c in self.path.columns))
        for i, m in enumerate(msgs):
            for c in DEVIATION_COLUMNS:
                v = dev[c][i]
                m[c] = int(v) if c == "leg" else (None if v != v else float(v))
        if fpa:
            gpa = np.degrees(np.arctan(self.path.slope(dev["along_m"]))).tolist()
            for m, g in zip(msgs, gpa, strict=True):
                f = m["fpa_deg"]
                ok = g == g and f is not None
                m.update(gpa_deg=g if g == g else None, gpa_err_deg=f - g if ok else None,
                         gpa_err_sigma_deg=m["fpa_sigma_deg"] if ok else None)
