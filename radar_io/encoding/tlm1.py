"""TLM1 telemetry uplink frames (radar-interface.md §8), built from ``firmware_specs/tlm1.toml``.

* :class:`TelemetryEncoder` — streaming ground-side encoder: measurement
  batches → frame bytes, one frame per valid sample (RX_GOOD = 1 and GO = 1;
  optionally at most one per ``cycle_s``); keeps the SEQ counter, the
  kinematics state and the per-channel saturation / unavailable counters
  across batches. :meth:`~TelemetryEncoder.encode_batch` is the numpy path,
  :meth:`~TelemetryEncoder.encode_frame` the per-frame (construct) path.
* :class:`TelemetryDecoder` — aircraft-side decoder: hunts for the sync word,
  checks the CRC, counts errors and SEQ gaps (numpy path :meth:`feed`,
  per-frame construct path :meth:`decode_frame`).
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import construct as cs
import numpy as np

from radar_io.decoding.measurement import Columns
from radar_io.encoding.kinematics import KINEMATIC_COLUMNS, Kinematics
from radar_io.errors import SpecError, UplinkError
from radar_io.wirespec.crc import crc_function, word_table
from radar_io.wirespec.frame import CrcSpec
from radar_io.wirespec.reading import crc_spec, keys, positive, read_toml, req, tables

SCALINGS = ("full_scale", "raw_bits", "zero")
#: how to get a missing source column
COLUMN_HINTS = {"dy_m": "decode with --path", "dz_m": "decode with --path",
                "along_m": "decode with --path", "xr_m": "decode with --site",
                "yr_m": "decode with --site", "hr_m": "decode with --site"}


@dataclass(frozen=True)
class ChannelSpec:
    """One i16 channel word of the frame."""

    number: int
    name: str
    offset: int
    source: str        #: measurement column ("" for a zero channel)
    scaling: str       #: one of SCALINGS
    full_scale: float  #: engineering value of +full_scale_count (full_scale scaling)
    unit: str = ""
    description: str = ""

    @property
    def column(self) -> str:
        """Name of the decoded value: the source column, or the channel name for a spare."""
        return self.source or self.name


@dataclass(frozen=True)
class TelemetrySpec:
    name: str
    spec_version: str
    length: int
    sync_word: int
    seq_offset: int
    full_scale_count: int
    cycle_s: float
    crc: CrcSpec
    channels: tuple[ChannelSpec, ...]
    kinematics: tuple[float, float, int]   #: window_s, min_span_s, min_samples
    path: str
    sha256: str


def load_tlm_spec(path: str | os.PathLike[str] | None = None) -> TelemetrySpec:
    """Load and validate ``firmware_specs/tlm1.toml`` (or ``path``); SpecError names the problem."""
    doc, p, sha = read_toml(path, "tlm1.toml")
    keys(doc, "frame crc kinematics channel", p)
    fr = req(doc, "frame", dict, p)
    where = f"{p} [frame]"
    keys(fr, "name spec_version length_bytes byte_order sync_word seq_offset full_scale_count "
         "cycle_s", where)
    length = req(fr, "length_bytes", int, where)
    if req(fr, "byte_order", str, where) != "big":
        raise SpecError(f"{where}: only byte_order = 'big' is supported")
    sync = req(fr, "sync_word", int, where)
    if not 0 < sync <= 0xFFFF:
        raise SpecError(f"{where}: sync_word must be a non-zero 16-bit value")
    seq_offset = req(fr, "seq_offset", int, where)
    full_count = req(fr, "full_scale_count", int, where)
    if not 1 <= full_count <= 32767:
        raise SpecError(f"{where}: full_scale_count must be 1 .. 32767")
    cycle = fr.get("cycle_s", 0.0)
    if (isinstance(cycle, bool) or not isinstance(cycle, (int, float))
            or not (cycle >= 0 and math.isfinite(cycle))):
        raise SpecError(f"{where}: cycle_s must be a number >= 0")
    crc = crc_spec(doc, p)
    if crc.offset + 2 != length:
        raise SpecError(f"{p} [crc]: the CRC word must be the last two bytes of the frame")
    used = {0: "sync", 1: "sync", seq_offset: "seq", seq_offset + 1: "seq",
            crc.offset: "crc", crc.offset + 1: "crc"}
    if len(used) != 6 or seq_offset % 2 or seq_offset < 0 or seq_offset + 2 > crc.offset:
        raise SpecError(f"{where}: seq_offset must be even and clear of the sync word and the CRC")
    channels = []
    for i, c in enumerate(tables(doc, "channel", p)):
        cw = f"{p} [[channel]] #{i + 1}"
        name = req(c, "name", str, cw)
        cw = f"{p} channel {name!r}"
        keys(c, "number name offset source scaling full_scale unit description", cw)
        off = req(c, "offset", int, cw)
        if off % 2:
            raise SpecError(f"{cw}: offset must be even (16-bit words)")
        scaling = req(c, "scaling", str, cw)
        if scaling not in SCALINGS:
            raise SpecError(f"{cw}: scaling must be one of {', '.join(SCALINGS)}")
        for b in (off, off + 1):
            if not 0 <= b < length or b in used:
                raise SpecError(f"{cw}: offset {off} overlaps another word or lies outside the frame")
            used[b] = name
        source = "" if scaling == "zero" else req(c, "source", str, cw)
        fs = positive(c, "full_scale", cw) if scaling == "full_scale" else 1.0
        channels.append(ChannelSpec(number=req(c, "number", int, cw), name=name, offset=off,
                                    source=source, scaling=scaling, full_scale=fs,
                                    unit=str(c.get("unit", "")),
                                    description=str(c.get("description", ""))))
    if len(used) != length:
        raise SpecError(f"{p}: bytes {sorted(set(range(length)) - set(used))} are not declared")
    for attr in ("number", "name", "column"):
        vals = [getattr(c, attr) for c in channels]
        if len(set(vals)) != len(vals):
            raise SpecError(f"{p}: channel {attr}s must be unique")
    k = doc.get("kinematics", {})
    if not isinstance(k, dict):
        raise SpecError(f"{p}: [kinematics] must be a table")
    keys(k, "window_s min_span_s min_samples", f"{p} [kinematics]")
    kin = (positive(k, "window_s", f"{p} [kinematics]", 1.0),
           positive(k, "min_span_s", f"{p} [kinematics]", 0.5),
           int(positive(k, "min_samples", f"{p} [kinematics]", 10)))
    if kin[1] > kin[0] or kin[2] < 2:
        raise SpecError(f"{p} [kinematics]: need min_span_s <= window_s and min_samples >= 2")
    return TelemetrySpec(
        name=str(fr.get("name", "TLM1")), spec_version=str(fr.get("spec_version", "unversioned")),
        length=length, sync_word=sync, seq_offset=seq_offset, full_scale_count=full_count,
        cycle_s=float(cycle), crc=crc, channels=tuple(sorted(channels, key=lambda c: c.number)),
        kinematics=kin, path=p, sha256=sha)


# ----------------------------------------------------------------- channel scaling
def channel_words(ch: ChannelSpec, values: np.ndarray, full_count: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wire words as uint16, saturated mask, unavailable mask) for one channel's values."""
    v = np.asarray(values, dtype=np.float64) if ch.scaling == "full_scale" else np.asarray(values)
    n = v.shape[0]
    none = np.zeros(n, dtype=bool)
    if ch.scaling == "zero":
        return np.zeros(n, dtype=np.uint16), none, none
    if ch.scaling == "raw_bits":
        return (v.astype(np.int64) & 0xFFFF).astype(np.uint16), none, none
    bad = np.isnan(v)  # no value: sent as 0, counted unavailable; ±inf saturates
    with np.errstate(invalid="ignore"):
        counts = np.rint(np.clip(np.where(bad, 0.0, v) / ch.full_scale, -2.0, 2.0) * full_count)
        sat = np.abs(v) > ch.full_scale
    counts = np.clip(counts, -full_count, full_count).astype(np.int64)
    return (counts & 0xFFFF).astype(np.uint16), sat, bad


def channel_values(ch: ChannelSpec, words: np.ndarray, full_count: int) -> np.ndarray:
    """Engineering values (raw_bits / zero: the integer word) from wire words (uint16)."""
    w = np.asarray(words).astype(np.int64) & 0xFFFF
    if ch.scaling == "raw_bits":
        return w
    signed = w - ((w >> 15) << 16)
    if ch.scaling == "zero":
        return signed
    return signed * (ch.full_scale / full_count)


def frame_struct(spec: TelemetrySpec) -> cs.Construct:
    """construct ``Struct`` of one frame's 16-bit wire words (sync, seq, channels, crc), from the spec."""
    items = [(0, "sync"), (spec.seq_offset, "seq"), (spec.crc.offset, "crc"),
             *((c.offset, c.name) for c in spec.channels)]
    return cs.Struct(*(name / cs.Int16ub for _, name in sorted(items))).compile()


def frame_crc(spec: TelemetrySpec, w: np.ndarray) -> np.ndarray:
    """CRC of each frame given as (n, L/2) native uint16 words (the words before the CRC word)."""
    t = word_table(spec.crc.poly)
    reg = np.full(w.shape[0], spec.crc.init, dtype=np.uint16)
    for k in range(spec.crc.offset // 2):
        reg = t.take(reg ^ w[:, k])
    return reg ^ np.uint16(spec.crc.xor_out)


def build_frames(spec: TelemetrySpec, seq: np.ndarray, words: np.ndarray) -> bytes:
    """Frames from SEQ values (n,) and channel wire words (n, channels) — the numpy path."""
    w = np.zeros((len(seq), spec.length // 2), dtype=np.uint16)
    w[:, 0] = spec.sync_word
    w[:, spec.seq_offset // 2] = np.asarray(seq) & 0xFFFF
    for k, ch in enumerate(spec.channels):
        w[:, ch.offset // 2] = words[:, k]
    w[:, spec.crc.offset // 2] = frame_crc(spec, w)
    return w.astype(">u2").tobytes()


# ----------------------------------------------------------------- encoder
def filter_kinematics(cols: Columns) -> dict[str, np.ndarray]:
    """The TLM1 kinematic sources from the tracking filter's columns: ``gs_mps`` as
    ``ground_speed_mps``, ``track_deg`` (0 … 360) folded into the channel's (-180, 180]."""
    trk = np.mod(np.asarray(cols["track_deg"], dtype=np.float64) + 180.0, 360.0) - 180.0
    trk[trk == -180.0] = 180.0
    return {"ground_speed_mps": np.asarray(cols["gs_mps"], dtype=np.float64), "track_deg": trk}


class TelemetryEncoder:
    """Measurement batches → TLM1 frames; state (SEQ, kinematics, counters) carries across batches.

    ``saturation[name]`` counts samples whose value lay beyond the channel's
    full scale (sent at ±full_scale_count); ``unavailable[name]`` counts frames
    where the value was NaN (sent as 0), e.g. ground speed before the
    kinematics window has filled. A batch with the tracking filter's ``gs_mps`` and
    ``track_deg`` (the live service's messages) sends those instead of the window's.
    """

    def __init__(self, spec: TelemetrySpec | None = None, *, cycle_s: float | None = None,
                 seq_start: int = 0) -> None:
        self.spec = spec = spec or load_tlm_spec()
        self.cycle_s = spec.cycle_s if cycle_s is None else float(cycle_s)
        if not (self.cycle_s >= 0 and math.isfinite(self.cycle_s)):
            raise UplinkError(f"cycle_s must be >= 0, got {cycle_s!r}")
        self.seq = seq_start & 0xFFFF
        self.frames = 0
        self.saturation = {c.name: 0 for c in spec.channels}
        self.unavailable = {c.name: 0 for c in spec.channels}
        self.kinematics = Kinematics(*spec.kinematics)
        self._needs_kin = any(c.source in KINEMATIC_COLUMNS for c in spec.channels)
        self._last_cycle: float | None = None
        self._struct = frame_struct(spec)
        self._crc = crc_function(spec.crc)

    def _sources(self, cols: Columns) -> dict[str, np.ndarray]:
        kin = None
        if self._needs_kin and "gs_mps" in cols and "track_deg" in cols:
            kin = filter_kinematics(cols)  # the tracking filter's (the live service)
        elif self._needs_kin and not all(k in cols for k in KINEMATIC_COLUMNS):
            kin = self.kinematics.update(cols)   # every batch, to keep the window current
        out = {}
        for c in self.spec.channels:
            if not c.source:
                continue
            if kin is not None and c.source in kin:
                out[c.source] = kin[c.source]
            elif c.source in cols:
                out[c.source] = np.asarray(cols[c.source])
            else:
                hint = COLUMN_HINTS.get(c.source)
                raise UplinkError(f"{self.spec.name} channel {c.number} ({c.name}) needs column "
                                  f"{c.source!r}" + (f" ({hint})" if hint else ""))
        return out

    def select(self, cols: Columns) -> np.ndarray:
        """Row indices that produce a frame: RX_GOOD = 1 and GO = 1 (and the first of each cycle)."""
        rows = np.flatnonzero((np.asarray(cols["rx_good"]) == 1) & (np.asarray(cols["go"]) == 1))
        if self.cycle_s > 0 and rows.size:
            cyc = np.floor(np.asarray(cols["tod_s"], dtype=np.float64)[rows] / self.cycle_s)
            prev = np.concatenate([[np.nan if self._last_cycle is None else self._last_cycle], cyc[:-1]])
            rows = rows[cyc != prev]
            self._last_cycle = float(cyc[-1])
        return rows

    def batch_words(self, cols: Columns) -> np.ndarray:
        """(n_frames, channels) wire words for a batch; updates the counters."""
        src = self._sources(cols)
        rows = self.select(cols)
        words = np.zeros((rows.size, len(self.spec.channels)), dtype=np.uint16)
        for k, c in enumerate(self.spec.channels):
            vals = src[c.source][rows] if c.source else np.zeros(rows.size)
            words[:, k], sat, bad = channel_words(c, vals, self.spec.full_scale_count)
            self.saturation[c.name] += int(sat.sum())
            self.unavailable[c.name] += int(bad.sum())
        return words

    def encode_batch(self, cols: Columns) -> bytes:
        """Frame bytes for a MeasurementBatch (or a mapping of its columns), in row order."""
        words = self.batch_words(cols)
        n = words.shape[0]
        seq = (self.seq + np.arange(n)) & 0xFFFF
        self.seq = (self.seq + n) & 0xFFFF
        self.frames += n
        return build_frames(self.spec, seq, words)

    def encode_frame(self, values: Mapping[str, float]) -> bytes:
        """One frame (construct path) from source values keyed by column; no validity check.

        Kinematic values are taken as given (NaN or absent → unavailable).
        """
        fields: dict[str, Any] = {"sync": self.spec.sync_word, "seq": self.seq, "crc": 0}
        for c in self.spec.channels:
            v = values.get(c.source, math.nan) if c.source else 0
            w, sat, bad = channel_words(c, np.array([v]), self.spec.full_scale_count)
            self.saturation[c.name] += int(sat[0])
            self.unavailable[c.name] += int(bad[0])
            fields[c.name] = int(w[0])
        body = self._struct.build(fields)
        at = self.spec.crc.offset
        self.seq = (self.seq + 1) & 0xFFFF
        self.frames += 1
        return body[:at] + self._crc(body[:at]).to_bytes(2, "big") + body[at + 2:]


# ----------------------------------------------------------------- decoder
class TelemetryDecoder:
    """Aircraft side: bytes → decoded channel values, framed by the one framer core.

    ``stats``: frames, crc_errors (sync word found but CRC wrong), implausible (0),
    bytes_discarded (while hunting), seq_gaps (frames lost, from SEQ modulo 2**16;
    a repeated SEQ counts 0, the RDR1 rule).
    """

    def __init__(self, spec: TelemetrySpec | None = None) -> None:
        from radar_io.framing.core import BatchFramer

        self.spec = spec = spec or load_tlm_spec()
        #: the one framer core (radar_io.framing.core), with the TLM1 format: same rules and
        #: counters as RDR1, including the SEQ-gap rule (a repeated SEQ counts 0)
        self.framer = BatchFramer(spec)
        self._struct = frame_struct(spec)
        self._crc = crc_function(spec.crc)

    @property
    def stats(self) -> dict[str, int]:
        """frames, crc_errors, implausible (always 0: TLM1 declares no limits),
        bytes_discarded, seq_gaps — the framer core's counters."""
        return self.framer.stats.as_dict()

    def feed(self, data: bytes | bytearray | memoryview) -> dict[str, np.ndarray]:
        """Decode every complete frame in the data so far: ``seq`` and one column per channel."""
        return self._columns(self.framer.feed(data))

    def flush(self) -> None:
        """End of stream: the incomplete tail is discarded."""
        self.framer.flush()

    def _columns(self, frames: np.ndarray) -> dict[str, np.ndarray]:
        spec = self.spec
        seq = frames[:, spec.seq_offset // 2].astype(np.int64)
        out = {"seq": seq}
        for c in spec.channels:
            out[c.column] = channel_values(c, frames[:, c.offset // 2], spec.full_scale_count)
        return out

    def decode_frame(self, frame: bytes) -> dict[str, Any]:
        """One frame (construct path): ``seq`` and one value per channel; UplinkError if invalid."""
        spec = self.spec
        if len(frame) != spec.length:
            raise UplinkError(f"{spec.name} frame must be {spec.length} bytes, got {len(frame)}")
        raw = self._struct.parse_stream(io.BytesIO(frame))
        if raw["sync"] != spec.sync_word:
            raise UplinkError(f"{spec.name}: bad sync word 0x{raw['sync']:04X}")
        if self._crc(frame[:spec.crc.offset]) != raw["crc"]:
            raise UplinkError(f"{spec.name}: CRC mismatch")
        out: dict[str, Any] = {"seq": raw["seq"]}
        for c in spec.channels:
            out[c.column] = channel_values(c, np.array([raw[c.name]]), spec.full_scale_count)[0].item()
        return out
