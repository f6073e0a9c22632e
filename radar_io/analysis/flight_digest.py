"""A recording reduced to what a flight report shows, in memory bounded by its size in
figures, not by its length.

:func:`digest_recording` streams a ``.rdrlog`` (or raw capture) through the batch decoder
(:func:`~radar_io.decoding.batch_decoder.iter_decode`) and reduces each decoded block at
once to:

* **exact running statistics**: frames, GO and RX GOOD frames, the framer's counters,
  the frame period (median TOD step, from a count of the distinct steps), the sync
  events and, per path element, DY / DZ sums of squares, maxima and along-track extent;
* **thinned rows for the figures**: every ``stride``-th frame of the kept columns, the
  stride doubling whenever more than ``max_rows`` rows are held (so between
  ``max_rows / 2`` and ``max_rows``), and per row the minimum of GO and RX GOOD and the
  time of the first SEQ discontinuity over its ``stride`` frames (a dropout shorter than
  the plotting step still shows).

A 1-hour recording at 1 kHz (3.6 M frames) holds the same few MB as a 10-minute one.
Time is the frame's TOD unwrapped past midnight, in seconds from the first frame
(``t_s``). The framer's cumulative counters are sampled after each decoded piece, which
puts CRC errors and SEQ gaps on the timeline with the resolution of one piece
(``piece_bytes``; 64 KiB ≈ 2 s at 1 kHz).

Annotations of the recording's event log (``<id>.events.jsonl``: notes, markers, test
point starts and ends, made live or with ``radar-io annotate``) are placed on that time
axis by their receive time, ``t_s = (t_ns − t_ns of the first chunk) / 1e9``; a test point
runs from a ``test_point_start`` to the next ``test_point_end`` of the same label (else the
next end; an unended one runs to the end of the recording) and gets exact DY / DZ RMS and
max |.| over its frames (:meth:`FlightDigest.test_points`).
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

#: decoded columns a report keeps (those present), thinned
KEEP = ("seq", "tod_s", "sr_m", "dsr_m", "el_deg", "del_deg", "az_deg", "daz_deg", "go",
        "rx_good", "sync", "x_m", "y_m", "h_m", "xr_m", "yr_m", "hr_m",
        "dy_m", "dz_m", "along_m", "leg")
#: flags reduced by their minimum over each thinned row's frames
FLAGS = ("go", "rx_good")
_DAY_S = 86400.0
MAX_ROWS = 16384


class Thinned:
    """Every ``stride``-th frame of some columns, ``stride`` a power of two doubled to keep at
    most ``max_rows`` rows; per row the minimum of each flag and the time of the first SEQ
    discontinuity (NaN: none) over the ``stride`` frames it stands for."""

    def __init__(self, max_rows: int = MAX_ROWS) -> None:
        self.max_rows = max(2, int(max_rows))
        self.stride = 1
        self.frames = 0  #: frames offered so far
        self.rows = 0
        self._cols: dict[str, list[np.ndarray]] = {}
        self._mins: dict[str, list[np.ndarray]] = {}
        self._jump: list[np.ndarray] = []

    def add(self, cols: dict[str, np.ndarray], flags: dict[str, np.ndarray],
            jump_t_s: np.ndarray) -> None:
        """One block: ``cols`` and ``flags`` per frame; ``jump_t_s`` the frame's time where
        its SEQ does not follow the previous frame's, NaN elsewhere."""
        m = int(jump_t_s.size)
        if m == 0:
            return
        g = self.frames + np.arange(m)
        bucket = g // self.stride
        starts = np.flatnonzero(np.diff(bucket, prepend=bucket[0] - 1))
        mins = {k: np.minimum.reduceat(np.asarray(v, dtype=np.int8), starts)
                for k, v in flags.items()}
        pos = np.where(np.isfinite(jump_t_s), np.arange(m), m)
        first = np.minimum.reduceat(pos, starts)
        jump = np.where(first < m, jump_t_s[np.minimum(first, m - 1)], np.nan)
        if self.frames % self.stride:  # the first bucket continues the last row
            for k, v in mins.items():
                last = self._mins[k][-1]
                last[-1] = min(last[-1], v[0])
            if np.isnan(self._jump[-1][-1]):
                self._jump[-1][-1] = jump[0]
            mins = {k: v[1:] for k, v in mins.items()}
            jump = jump[1:]
        keep = starts if self.frames % self.stride == 0 else starts[1:]
        if keep.size:  # new rows (the last part is never empty: it holds the open row)
            for k, v in cols.items():
                self._cols.setdefault(k, []).append(np.asarray(v)[keep])
            for k, v in mins.items():
                self._mins.setdefault(k, []).append(v)
            self._jump.append(jump)
        self.frames += m
        self.rows += int(keep.size)
        while self.rows > self.max_rows:
            self._halve()

    def _halve(self) -> None:
        """Stride × 2: every other row; flags and jumps combined pairwise."""
        def pairs(a: np.ndarray, combine: Callable[[np.ndarray, np.ndarray], np.ndarray]
                  ) -> np.ndarray:
            out = a[0::2].copy()
            b = a[1::2]
            out[:b.size] = combine(out[:b.size], b)
            return out

        self._cols = {k: [np.concatenate(v)[0::2]] for k, v in self._cols.items()}
        self._mins = {k: [pairs(np.concatenate(v), np.minimum)] for k, v in self._mins.items()}
        self._jump = [pairs(np.concatenate(self._jump), lambda a, b: np.where(np.isnan(a), b, a))]
        self.stride *= 2
        self.rows = int(self._jump[0].size)

    def columns(self) -> dict[str, np.ndarray]:
        return {k: np.concatenate(v) for k, v in self._cols.items()}

    def flag_minima(self) -> dict[str, np.ndarray]:
        return {k: np.concatenate(v) for k, v in self._mins.items()}

    def jumps(self) -> np.ndarray:
        return np.concatenate(self._jump) if self._jump else np.empty(0)


@dataclass
class _TestPoint:
    """One test point: its label, its span on the ``t_s`` axis and its DY / DZ sums."""

    label: str
    from_s: float
    to_s: float
    text: str = ""
    samples: int = 0
    dy_sq: float = 0.0
    dy_max: float = np.nan
    dz_sq: float = 0.0
    dz_n: int = 0
    dz_max: float = np.nan

    def add(self, t: np.ndarray, c: dict[str, np.ndarray]) -> None:
        sel = (t >= self.from_s) & (t <= self.to_s)
        if not sel.any() or "dy_m" not in c:
            return
        for col, sq, n, mx in (("dy_m", "dy_sq", "samples", "dy_max"),
                               ("dz_m", "dz_sq", "dz_n", "dz_max")):
            v = np.asarray(c[col])[sel]
            v = v[np.isfinite(v)]
            if v.size:
                setattr(self, sq, getattr(self, sq) + float(np.sum(v ** 2)))
                setattr(self, n, getattr(self, n) + int(v.size))
                m = float(np.max(np.abs(v)))
                setattr(self, mx, m if np.isnan(getattr(self, mx)) else max(getattr(self, mx), m))


def test_point_spans(annotations: list[dict[str, Any]]) -> list[_TestPoint]:
    """Test points from annotations with ``t_s`` (oldest first): a ``test_point_start``
    ends at the next ``test_point_end`` of its label, else at the next end of any label;
    one never ended runs to +inf (the end of the recording)."""
    open_: list[_TestPoint] = []
    out: list[_TestPoint] = []
    for a in sorted(annotations, key=lambda a: a["t_s"]):
        kind = a.get("annotation_kind")
        if kind == "test_point_start":
            tp = _TestPoint(str(a.get("label") or f"TP{len(out) + len(open_) + 1}"),
                            float(a["t_s"]), np.inf, str(a.get("text") or ""))
            open_.append(tp)
            out.append(tp)
        elif kind == "test_point_end" and open_:
            same = [tp for tp in open_ if tp.label == a.get("label")]
            tp = same[0] if same else open_[0]
            tp.to_s = float(a["t_s"])
            open_.remove(tp)
    return out


@dataclass
class _Leg:
    samples: int = 0
    along_from_m: float = np.inf
    along_to_m: float = -np.inf
    dy_sq: float = 0.0
    dy_max: float = -np.inf
    dz_sq: float = 0.0
    dz_n: int = 0
    dz_max: float = np.nan


@dataclass
class FlightDigest:
    """Thinned columns for the figures plus exact statistics; see the module docstring."""

    source: str
    #: thinned rows (every ``stride``-th frame) of the kept columns and ``t_s``
    columns: dict[str, np.ndarray]
    stats: dict[str, int]
    #: framer counters after each decoded piece: t_s, crc_errors, seq_gaps (cumulative)
    counter_t_s: np.ndarray
    counter_crc: np.ndarray
    counter_gaps: np.ndarray
    frame_period_s: float
    n_frames: int = 0
    go_frames: int = 0
    rx_good_frames: int = 0
    duration_s: float = 0.0
    stride: int = 1
    #: per thinned row: minimum of GO and RX GOOD over its frames
    flag_min: dict[str, np.ndarray] = field(default_factory=dict)
    #: per thinned row: time of its first SEQ discontinuity (NaN: none)
    seq_jump_t_s: np.ndarray = field(default_factory=lambda: np.empty(0))
    sync: list[dict[str, Any]] = field(default_factory=list)
    leg_stats: dict[int, _Leg] = field(default_factory=dict)
    header: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    path: ReferencePath | None = None
    site: Site | None = None
    #: alarm raise / clear / ack records from ``<recording>.events.jsonl`` (service/alarms.py)
    alarm_events: list[dict[str, Any]] = field(default_factory=list)
    #: annotation events, each with ``t_s`` on the time axis (module docstring)
    annotations: list[dict[str, Any]] = field(default_factory=list)
    test_point_stats: list[_TestPoint] = field(default_factory=list)
    #: what the recording was decoded with (spec, calibration, site): for a second pass
    decode_options: dict[str, Any] = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return self.n_frames

    @property
    def t_s(self) -> np.ndarray:
        return self.columns["t_s"]

    def plot_index(self, max_points: int = 4000) -> np.ndarray:
        """Indices into the thinned rows: about ``max_points`` evenly strided."""
        return decimate_index(int(self.columns["t_s"].size), max_points)

    def summary(self) -> dict[str, Any]:
        """Duration, frames, CRC errors, gaps, GO time, RX GOOD fraction (SI units)."""
        n = self.n_frames
        return {
            "duration_s": self.duration_s,
            "frames": n,
            "crc_errors": int(self.stats.get("crc_errors", 0)),
            "seq_gaps": int(self.stats.get("seq_gaps", 0)),
            "bytes_discarded": int(self.stats.get("bytes_discarded", 0)),
            "go_time_s": float(self.go_frames * self.frame_period_s),
            "rx_good_fraction": self.rx_good_frames / n if n else 0.0,
            "sync_events": len(self.sync),
        }

    def sync_events(self) -> list[dict[str, Any]]:
        """SYNC 0→1 edges: index, SEQ, TOD, time from start and SR/EL/AZ at the edge."""
        return [dict(e) for e in self.sync]

    def test_points(self) -> list[dict[str, Any]]:
        """Per test point: label, text, from_s, to_s, samples, DY / DZ RMS and max |.| (m;
        NaN without a path or frames)."""
        out = []
        for tp in self.test_point_stats:
            out.append({"label": tp.label, "text": tp.text, "from_s": tp.from_s,
                        "to_s": min(tp.to_s, self.duration_s), "samples": tp.samples,
                        "dy_rms_m": float(np.sqrt(tp.dy_sq / tp.samples)) if tp.samples
                        else float("nan"), "dy_max_abs_m": tp.dy_max,
                        "dz_rms_m": float(np.sqrt(tp.dz_sq / tp.dz_n)) if tp.dz_n
                        else float("nan"), "dz_max_abs_m": tp.dz_max})
        return out

    def legs(self) -> list[dict[str, Any]]:
        """DY / DZ RMS and maximum |value| per path element (needs a path)."""
        out = []
        for leg in sorted(self.leg_stats):
            a = self.leg_stats[leg]
            out.append({"leg": leg, "kind": "turn" if leg % 2 else "straight",
                        "samples": a.samples, "along_from_m": a.along_from_m,
                        "along_to_m": a.along_to_m,
                        "dy_rms_m": float(np.sqrt(a.dy_sq / a.samples)),
                        "dy_max_abs_m": a.dy_max,
                        "dz_rms_m": float(np.sqrt(a.dz_sq / a.dz_n)) if a.dz_n else float("nan"),
                        "dz_max_abs_m": a.dz_max})
        return out


class _Reducer:
    """Folds decoded blocks into the statistics and thinned rows of a :class:`FlightDigest`."""

    def __init__(self, max_rows: int) -> None:
        self.thin = Thinned(max_rows)
        self.n = self.go = self.good = 0
        self.t0: float | None = None
        self.prev_tod = 0.0
        self.wraps = 0
        self.prev_sync = True  # a recording starting with SYNC high has no edge there
        self.prev_seq: int | None = None
        self.steps: dict[float, int] = {}
        self.t_last = 0.0
        self.sync: list[dict[str, Any]] = []
        self.legs: dict[int, _Leg] = {}
        self.counter_t: list[float] = []
        self.counter_crc: list[int] = []
        self.counter_gap: list[int] = []
        self.test_points: list[_TestPoint] = []

    def add(self, c: dict[str, np.ndarray], stats: dict[str, int]) -> None:
        tod = np.asarray(c["tod_s"], dtype=np.float64)
        m = tod.size
        if self.t0 is None:
            self.t0 = self.prev_tod = float(tod[0])
        back = np.diff(tod, prepend=self.prev_tod) < -_DAY_S / 2
        prev_u = self.prev_tod + _DAY_S * self.wraps  # the previous frame, unwrapped
        tod_u = tod + _DAY_S * (self.wraps + np.cumsum(back))
        self.wraps += int(back.sum())
        steps = np.diff(tod_u, prepend=prev_u)[0 if self.n else 1:]
        vals, counts = np.unique(steps, return_counts=True)
        for v, k in zip(vals.tolist(), counts.tolist(), strict=True):
            self.steps[v] = self.steps.get(v, 0) + k
        self.prev_tod = float(tod[-1])
        t = tod_u - self.t0
        self.t_last = float(t[-1])
        self.go += int(np.count_nonzero(c["go"]))
        self.good += int(np.count_nonzero(c["rx_good"]))
        # SEQ discontinuities and sync edges, continuing across blocks
        seq = np.asarray(c["seq"]).astype(np.int64)
        prev = np.concatenate(([seq[0] - 1 if self.prev_seq is None else self.prev_seq],
                               seq[:-1]))
        jump_t = np.where(seq - prev != 1, t, np.nan)
        self.prev_seq = int(seq[-1])
        s = np.asarray(c["sync"]).astype(bool)
        edges = np.flatnonzero(s & ~np.concatenate(([self.prev_sync], s[:-1])))
        self.prev_sync = bool(s[-1])
        for i in edges.tolist():
            self.sync.append({"index": len(self.sync), "seq": int(c["seq"][i]),
                              "tod_s": float(c["tod_s"][i]), "t_s": float(t[i]),
                              "rx_good": bool(c["rx_good"][i]), "sr_m": float(c["sr_m"][i]),
                              "el_deg": float(c["el_deg"][i]), "az_deg": float(c["az_deg"][i])})
        if "dy_m" in c:
            self._legs(c)
            for tp in self.test_points:
                tp.add(t, c)
        self.thin.add({**{k: c[k] for k in KEEP if k in c}, "t_s": t},
                      {k: c[k] for k in FLAGS}, jump_t)
        self.n += m
        self.counter_t.append(self.t_last)
        self.counter_crc.append(int(stats.get("crc_errors", 0)))
        self.counter_gap.append(int(stats.get("seq_gaps", 0)))

    def _legs(self, c: dict[str, np.ndarray]) -> None:
        leg_col = np.asarray(c["leg"])
        ok = np.isfinite(c["dy_m"]) & (leg_col >= 0)
        for leg in np.unique(leg_col[ok]).tolist():
            sel = ok & (leg_col == leg)
            dy, dz, along = c["dy_m"][sel], c["dz_m"][sel], c["along_m"][sel]
            a = self.legs.setdefault(int(leg), _Leg())
            a.samples += int(sel.sum())
            a.along_from_m = min(a.along_from_m, float(along.min()))
            a.along_to_m = max(a.along_to_m, float(along.max()))
            a.dy_sq += float(np.sum(dy ** 2))
            a.dy_max = max(a.dy_max, float(np.max(np.abs(dy))))
            fz = np.isfinite(dz)
            if fz.any():
                a.dz_sq += float(np.sum(dz[fz] ** 2))
                a.dz_n += int(fz.sum())
                zmax = float(np.max(np.abs(dz[fz])))
                a.dz_max = zmax if np.isnan(a.dz_max) else max(a.dz_max, zmax)

    def period_s(self) -> float:
        """The median TOD step (1 ms when there is none or it is not positive)."""
        if not self.steps:
            return 1e-3
        vals = np.array(sorted(self.steps))
        cum = np.cumsum([self.steps[v] for v in vals.tolist()])
        total = int(cum[-1])
        lo = vals[np.searchsorted(cum, (total - 1) // 2 + 1)]
        hi = vals[np.searchsorted(cum, total // 2 + 1)]
        period = float((lo + hi) / 2)
        return period if period > 0 else 1e-3


def digest_recording(path: str | os.PathLike[str], *, site: Site | None = None,
                     calibration: Calibration | None = None,
                     ref_path: ReferencePath | None = None, spec: Any = None,
                     piece_bytes: int = 1 << 16, max_rows: int = MAX_ROWS,
                     progress: Callable[[int, int], None] | None = None) -> FlightDigest:
    """Decode a recording (or raw capture) into a :class:`FlightDigest` (bounded memory)."""
    from radar_io.coordinates.reference_path import add_deviation
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import ReadReport, RecordingReader, is_recording, iter_payloads

    if not os.path.isfile(path):
        raise ConfigError(f"recording not found: {path}")
    if ref_path is not None and ref_path.frame == "runway" and site is None:
        raise ConfigError(f"{ref_path.name or 'path'}: a runway-frame reference path needs --site")
    header: dict[str, Any] = {}
    first_t_ns: int | None = None
    if is_recording(path):
        with RecordingReader(path) as r:
            header = dict(r.header)
            first_t_ns = next((c.t_ns for c in r), None)
    events: list[dict[str, Any]] = []
    side = Path(path).with_suffix(".events.jsonl")
    if side.is_file():
        from radar_io.service.alarms import read_events

        events = read_events(side)
    notes = [{**e, "t_s": (int(e["t_ns"]) - first_t_ns) / 1e9} for e in events
             if e.get("kind") == "annotation" and isinstance(e.get("t_ns"), int)
             and first_t_ns is not None]
    report = ReadReport()
    red = _Reducer(max_rows)
    red.test_points = test_point_spans(notes)
    stats: dict[str, int] = {}
    for batch in iter_decode(iter_payloads(path, piece_bytes, progress, report), spec=spec,
                             calibration=calibration, site=site):
        stats = batch.stats
        if len(batch) == 0:
            continue
        if ref_path is not None:
            batch = add_deviation(batch, ref_path)
        red.add({k: batch[k] for k in (*KEEP, "tod_s") if k in batch}, stats)
    if red.n == 0:
        raise ConfigError(f"{path}: no RDR1 frames found")
    thin = red.thin
    return FlightDigest(
        source=str(path), columns=thin.columns(), stats=dict(stats),
        counter_t_s=np.asarray(red.counter_t), counter_crc=np.asarray(red.counter_crc),
        counter_gaps=np.asarray(red.counter_gap), frame_period_s=red.period_s(),
        n_frames=red.n, go_frames=red.go, rx_good_frames=red.good, duration_s=red.t_last,
        stride=thin.stride, flag_min=thin.flag_minima(), seq_jump_t_s=thin.jumps(),
        sync=red.sync, leg_stats=red.legs, header=header, problems=list(report.problems),
        path=ref_path, site=site,
        alarm_events=[e for e in events if e.get("type") == "alarm"],
        annotations=sorted(notes, key=lambda e: e["t_s"]), test_point_stats=red.test_points,
        decode_options={"spec": spec, "calibration": calibration, "site": site})


def decimate_index(n: int, max_points: int = 4000) -> np.ndarray:
    """Indices of at most about ``max_points`` evenly strided samples of ``n`` (for plotting)."""
    step = max(1, int(np.ceil(n / max_points)))
    return np.arange(0, n, step)
