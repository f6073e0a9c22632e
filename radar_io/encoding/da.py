"""D/A recorder words (radar-interface.md §7), built from ``firmware_specs/da_words.toml``.

:class:`DAEncoder` turns every measurement row into one group of words (one per
channel, in channel order, big-endian u16): PEN UP while the sample is NG or
GO = 0 (and on a word whose value is NaN), channel number, 12-bit two's
complement data with saturation counted per channel. :func:`decode_da_words`
is the inverse, for checks and playback.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from radar_io.decoding.measurement import Columns
from radar_io.encoding.tlm1 import COLUMN_HINTS
from radar_io.errors import SpecError, UplinkError
from radar_io.wirespec.reading import keys, positive, read_toml, req, tables

PEN_UP_DATA = ("hold", "zero")
#: sources the encoder derives from other columns when the batch lacks them:
#: Z = -H, the right-handed down axis of radar-interface.md §5 (channel 8 of §7)
DERIVED_SOURCES = {"z_m": ("h_m", -1.0)}


def source_values(cols: Columns, source: str) -> np.ndarray | None:
    """The column ``source`` from ``cols`` (derived ones such as ``z_m`` = -``h_m`` computed), or None."""
    if source in cols:
        return np.asarray(cols[source], dtype=np.float64)
    if source in DERIVED_SOURCES:
        base, sign = DERIVED_SOURCES[source]
        if base in cols:
            return sign * np.asarray(cols[base], dtype=np.float64)
    return None


@dataclass(frozen=True)
class DAChannel:
    number: int
    name: str
    source: str
    full_scale: float
    gain: float = 1.0
    unit: str = ""
    description: str = ""


@dataclass(frozen=True)
class DASpec:
    name: str
    spec_version: str
    pen_up_mask: int
    channel_mask: int
    data_mask: int
    pen_up_data: str
    channels: tuple[DAChannel, ...]
    path: str
    sha256: str

    @property
    def data_bits(self) -> int:
        return self.data_mask.bit_count()

    @property
    def data_shift(self) -> int:
        return (self.data_mask & -self.data_mask).bit_length() - 1

    @property
    def channel_shift(self) -> int:
        return (self.channel_mask & -self.channel_mask).bit_length() - 1

    def lsb(self, ch: DAChannel) -> float:
        """Weight of one data count: full_scale / 2**(data_bits - 1)."""
        return ch.full_scale / (1 << (self.data_bits - 1))


def _contiguous(mask: int) -> bool:
    low = mask & -mask
    return mask > 0 and ((mask + low) & mask) == 0


def load_da_spec(path: str | os.PathLike[str] | None = None) -> DASpec:
    """Load and validate ``firmware_specs/da_words.toml`` (or ``path``)."""
    doc, p, sha = read_toml(path, "da_words.toml")
    keys(doc, "word channel", p)
    w = req(doc, "word", dict, p)
    where = f"{p} [word]"
    keys(w, "name spec_version byte_order pen_up_mask channel_mask data_mask pen_up_data", where)
    if req(w, "byte_order", str, where) != "big":
        raise SpecError(f"{where}: only byte_order = 'big' is supported")
    pen, chm, data = (req(w, k, int, where) for k in ("pen_up_mask", "channel_mask", "data_mask"))
    if pen.bit_count() != 1 or not all(_contiguous(m) for m in (chm, data)) \
            or pen & chm or pen & data or chm & data or (pen | chm | data) != 0xFFFF:
        raise SpecError(f"{where}: pen_up_mask (one bit), channel_mask and data_mask (contiguous) "
                        "must be disjoint and cover the 16-bit word")
    if data.bit_count() < 2:
        raise SpecError(f"{where}: data_mask needs at least 2 bits")
    pen_data = w.get("pen_up_data", "hold")
    if pen_data not in PEN_UP_DATA:
        raise SpecError(f"{where}: pen_up_data must be one of {', '.join(PEN_UP_DATA)}")
    channels = []
    max_ch = chm >> ((chm & -chm).bit_length() - 1)
    for i, c in enumerate(tables(doc, "channel", p)):
        cw = f"{p} [[channel]] #{i + 1}"
        name = req(c, "name", str, cw)
        cw = f"{p} channel {name!r}"
        keys(c, "number name source full_scale gain unit description", cw)
        number = req(c, "number", int, cw)
        if not 1 <= number <= max_ch + 1:
            raise SpecError(f"{cw}: number must be 1 .. {max_ch + 1}")
        gain = c.get("gain", 1.0)
        if isinstance(gain, bool) or not isinstance(gain, (int, float)) or gain == 0:
            raise SpecError(f"{cw}: gain must be a non-zero number")
        channels.append(DAChannel(number=number, name=name, source=req(c, "source", str, cw),
                                  full_scale=positive(c, "full_scale", cw), gain=float(gain),
                                  unit=str(c.get("unit", "")),
                                  description=str(c.get("description", ""))))
    for attr in ("number", "name"):
        vals = [getattr(c, attr) for c in channels]
        if len(set(vals)) != len(vals):
            raise SpecError(f"{p}: channel {attr}s must be unique")
    return DASpec(name=str(w.get("name", "DA")), spec_version=str(w.get("spec_version", "unversioned")),
                  pen_up_mask=pen, channel_mask=chm, data_mask=data, pen_up_data=pen_data,
                  channels=tuple(sorted(channels, key=lambda c: c.number)), path=p, sha256=sha)


class DAEncoder:
    """Measurement batches → D/A words, one group of ``len(channels)`` words per row.

    ``saturation[name]`` counts pen-down words clamped to the data range;
    ``samples`` and ``pen_up_samples`` count rows (all / NG or GO = 0).
    """

    def __init__(self, spec: DASpec | None = None) -> None:
        self.spec = spec = spec or load_da_spec()
        self.saturation = {c.name: 0 for c in spec.channels}
        self.samples = 0
        self.pen_up_samples = 0
        half = 1 << (spec.data_bits - 1)
        self._range = (-half, half - 1)
        self._held = np.zeros(len(spec.channels), dtype=np.int64)

    def words(self, cols: Columns) -> np.ndarray:
        """(rows, channels) uint16 words for a batch; updates the counters and the held data."""
        spec = self.spec
        src: dict[str, np.ndarray] = {}
        for c in spec.channels:
            values = source_values(cols, c.source)
            if values is None:
                hint = COLUMN_HINTS.get(c.source)
                raise UplinkError(f"{spec.name} channel {c.number} ({c.name}) needs column "
                                  f"{c.source!r}" + (f" ({hint})" if hint else ""))
            src[c.source] = values
        valid = (np.asarray(cols["rx_good"]) == 1) & (np.asarray(cols["go"]) == 1)
        n = valid.size
        out = np.empty((n, len(spec.channels)), dtype=np.uint16)
        lo, hi = self._range
        for k, c in enumerate(spec.channels):
            v = c.gain * src[c.source]
            down = valid & np.isfinite(v)
            counts = np.rint(np.where(down, v, 0.0) / spec.lsb(c))
            sat = down & ((counts < lo) | (counts > hi))
            counts = np.clip(counts, lo, hi).astype(np.int64)
            self.saturation[c.name] += int(sat.sum())
            if spec.pen_up_data == "hold":   # last pen-down data, carried across batches
                last = np.maximum.accumulate(np.where(down, np.arange(n), -1))
                counts = np.where(last >= 0, counts[np.maximum(last, 0)], self._held[k])
                if n:
                    self._held[k] = counts[-1]
            else:
                counts = np.where(down, counts, 0)
            word = ((c.number - 1) << spec.channel_shift) | ((counts << spec.data_shift) & spec.data_mask)
            out[:, k] = np.where(down, word, word | spec.pen_up_mask)
        self.samples += n
        self.pen_up_samples += int(n - valid.sum())
        return out

    def encode_batch(self, cols: Columns) -> bytes:
        """Big-endian u16 words for a MeasurementBatch (or a mapping of its columns)."""
        return self.words(cols).astype(">u2").tobytes()


@dataclass
class DAWords:
    """Decoded D/A words: (samples, channels) arrays in channel order."""

    channels: tuple[str, ...]
    values: np.ndarray     #: engineering values (data * LSB / gain)
    counts: np.ndarray     #: signed data counts
    pen_up: np.ndarray     #: bool


def decode_da_words(data: bytes | bytearray | memoryview, spec: DASpec | None = None) -> DAWords:
    """Decode whole groups of D/A words; UplinkError if the length or a channel number is wrong."""
    spec = spec or load_da_spec()
    nch = len(spec.channels)
    if len(data) % (2 * nch):
        raise UplinkError(f"{spec.name}: {len(data)} bytes is not a whole number of "
                          f"{nch}-word samples")
    w = np.frombuffer(bytes(data), dtype=">u2").astype(np.int64).reshape(-1, nch)
    want = np.array([c.number - 1 for c in spec.channels])
    got = (w & spec.channel_mask) >> spec.channel_shift
    if np.any(got != want):
        row = int(np.flatnonzero(np.any(got != want, axis=1))[0])
        raise UplinkError(f"{spec.name}: sample {row} has channel numbers {got[row].tolist()}, "
                          f"expected {want.tolist()}")
    bits = spec.data_bits
    raw = (w & spec.data_mask) >> spec.data_shift
    counts = raw - ((raw >> (bits - 1)) << bits)
    scale = np.array([spec.lsb(c) / c.gain for c in spec.channels])
    return DAWords(channels=tuple(c.name for c in spec.channels), values=counts * scale,
                   counts=counts, pen_up=(w & spec.pen_up_mask) != 0)
