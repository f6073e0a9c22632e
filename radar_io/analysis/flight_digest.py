"""A recording reduced to what a flight report shows: columns, link health, sync events, legs.

:func:`digest_recording` streams a ``.rdrlog`` (or raw capture) through the batch
decoder (:func:`~radar_io.decoding.decoders.iter_decode`) and keeps only the columns
a report plots, so a 10-minute recording at 1 kHz stays a few tens of MB. Time is the
frame's TOD unwrapped past midnight, in seconds from the first frame (``t_s``).
The framer's cumulative counters are sampled after each decoded piece, which puts
CRC errors and SEQ gaps on the timeline with the resolution of one piece
(``piece_bytes``; 64 KiB ≈ 2 s at 1 kHz).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from radar_io.coordinates.reference_path import ReferencePath
from radar_io.coordinates.transforms import Site
from radar_io.decoding.biases import Calibration
from radar_io.errors import ConfigError

#: decoded columns a report keeps (those present)
KEEP = ("seq", "tod_s", "sr_m", "dsr_m", "el_deg", "del_deg", "az_deg", "daz_deg", "go",
        "rx_good", "sync", "x_m", "y_m", "h_m", "xr_m", "yr_m", "hr_m",
        "dy_m", "dz_m", "along_m", "leg")
_DAY_S = 86400.0


@dataclass
class FlightDigest:
    """Decoded columns (numpy) plus link counters; see the module docstring."""

    source: str
    columns: dict[str, np.ndarray]
    stats: dict[str, int]
    #: framer counters after each decoded piece: t_s, crc_errors, seq_gaps (cumulative)
    counter_t_s: np.ndarray
    counter_crc: np.ndarray
    counter_gaps: np.ndarray
    frame_period_s: float
    header: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    path: ReferencePath | None = None
    site: Site | None = None
    #: alarm raise / clear / ack records from ``<recording>.events.jsonl`` (service/alarms.py)
    alarm_events: list[dict[str, Any]] = field(default_factory=list)

    @property
    def frames(self) -> int:
        return int(self.columns["t_s"].size)

    @property
    def t_s(self) -> np.ndarray:
        return self.columns["t_s"]

    def summary(self) -> dict[str, Any]:
        """Duration, frames, CRC errors, gaps, GO time, RX GOOD fraction (SI units)."""
        n = self.frames
        t = self.t_s
        go = self.columns["go"].astype(bool)
        good = self.columns["rx_good"].astype(bool)
        return {
            "duration_s": float(t[-1] - t[0]) if n else 0.0,
            "frames": n,
            "crc_errors": int(self.stats.get("crc_errors", 0)),
            "seq_gaps": int(self.stats.get("seq_gaps", 0)),
            "bytes_discarded": int(self.stats.get("bytes_discarded", 0)),
            "go_time_s": float(go.sum() * self.frame_period_s),
            "rx_good_fraction": float(good.mean()) if n else 0.0,
            "sync_events": len(self.sync_events()),
        }

    def sync_events(self) -> list[dict[str, Any]]:
        """SYNC 0→1 edges: index, SEQ, TOD, time from start and SR/EL/AZ at the edge."""
        c = self.columns
        s = c["sync"].astype(bool)
        idx = np.flatnonzero(s & ~np.concatenate(([True], s[:-1])))
        return [{"index": k, "seq": int(c["seq"][i]), "tod_s": float(c["tod_s"][i]),
                 "t_s": float(c["t_s"][i]), "rx_good": bool(c["rx_good"][i]),
                 "sr_m": float(c["sr_m"][i]), "el_deg": float(c["el_deg"][i]),
                 "az_deg": float(c["az_deg"][i])} for k, i in enumerate(idx.tolist())]

    def legs(self) -> list[dict[str, Any]]:
        """DY / DZ RMS and maximum |value| per path element (needs a path)."""
        if "dy_m" not in self.columns:
            return []
        c = self.columns
        ok = np.isfinite(c["dy_m"]) & (c["leg"] >= 0)
        out = []
        for leg in np.unique(c["leg"][ok]).tolist():
            sel = ok & (c["leg"] == leg)
            dy, dz = c["dy_m"][sel], c["dz_m"][sel]
            out.append({"leg": int(leg), "kind": "turn" if leg % 2 else "straight",
                        "samples": int(sel.sum()),
                        "along_from_m": float(c["along_m"][sel].min()),
                        "along_to_m": float(c["along_m"][sel].max()),
                        "dy_rms_m": float(np.sqrt(np.mean(dy ** 2))),
                        "dy_max_abs_m": float(np.max(np.abs(dy))),
                        "dz_rms_m": float(np.sqrt(np.nanmean(dz ** 2))),
                        "dz_max_abs_m": float(np.nanmax(np.abs(dz)))})
        return out


def digest_recording(path: str | os.PathLike[str], *, site: Site | None = None,
                     calibration: Calibration | None = None,
                     ref_path: ReferencePath | None = None, spec: Any = None,
                     piece_bytes: int = 1 << 16,
                     progress: Callable[[int, int], None] | None = None) -> FlightDigest:
    """Decode a recording (or raw capture) into a :class:`FlightDigest`."""
    from radar_io.coordinates.reference_path import add_deviation
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import ReadReport, RecordingReader, is_recording, iter_payloads

    if not os.path.isfile(path):
        raise ConfigError(f"recording not found: {path}")
    if ref_path is not None and ref_path.frame == "runway" and site is None:
        raise ConfigError(f"{ref_path.name or 'path'}: a runway-frame reference path needs --site")
    header: dict[str, Any] = {}
    if is_recording(path):
        with RecordingReader(path) as r:
            header = dict(r.header)
    report = ReadReport()
    parts: dict[str, list[np.ndarray]] = {}
    c_row: list[int] = []
    rows = 0
    c_crc: list[int] = []
    c_gap: list[int] = []
    stats: dict[str, int] = {}
    for batch in iter_decode(iter_payloads(path, piece_bytes, progress, report), spec=spec,
                             calibration=calibration, site=site):
        stats = batch.stats
        if len(batch) == 0:
            continue
        if ref_path is not None:
            batch = add_deviation(batch, ref_path)
        for k in KEEP:
            if k in batch:
                parts.setdefault(k, []).append(np.asarray(batch[k]))
        rows += len(batch)
        c_row.append(rows - 1)
        c_crc.append(int(stats.get("crc_errors", 0)))
        c_gap.append(int(stats.get("seq_gaps", 0)))
    if not parts:
        raise ConfigError(f"{path}: no RDR1 frames found")
    cols = {k: np.concatenate(v) for k, v in parts.items()}
    tod = cols["tod_s"].astype(np.float64)
    wraps = np.cumsum(np.diff(tod, prepend=tod[0]) < -_DAY_S / 2)
    tod_u = tod + _DAY_S * wraps
    t0 = tod_u[0]
    cols["t_s"] = tod_u - t0
    steps = np.diff(tod_u)
    period = float(np.median(steps)) if steps.size else 1e-3
    if not period > 0:
        period = 1e-3
    events: list[dict[str, Any]] = []
    side = Path(path).with_suffix(".events.jsonl")
    if side.is_file():
        from radar_io.service.alarms import read_events

        events = [e for e in read_events(side) if e.get("type") == "alarm"]
    return FlightDigest(alarm_events=events, source=str(path), columns=cols, stats=dict(stats),
                        counter_t_s=cols["t_s"][np.asarray(c_row, dtype=np.int64)],
                        counter_crc=np.asarray(c_crc),
                        counter_gaps=np.asarray(c_gap), frame_period_s=period, header=header,
                        problems=list(report.problems), path=ref_path, site=site)


def decimate_index(n: int, max_points: int = 4000) -> np.ndarray:
    """Indices of at most about ``max_points`` evenly strided samples of ``n`` (for plotting)."""
    step = max(1, int(np.ceil(n / max_points)))
    return np.arange(0, n, step)
