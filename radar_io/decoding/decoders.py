"""Decoders: accepted frames → measurements (radar-interface.md §1, §2, §4, §5).

Two decoders, both *built from* the one :class:`~radar_io.wirespec.frame.FrameSpec`:

* :class:`FrameDecoder` parses one frame with a construct ``Struct`` generated
  from the spec and returns a dict keyed by the column names — for live use
  and debugging;
* :class:`BatchDecoder` decodes an (N, L/2) array of frame words at once with
  numpy — for files and the benchmark. Word → value tables are built by
  evaluating the spec's encoding for every raw code, and coordinates use exact
  float64 cos/sin tables of every quantised angle, combined with the angle-sum
  identity (so no float32 shortcut and no per-sample trigonometry).

A measurement's columns, in order: :data:`DECODE_COLUMNS`, then the extra
status flags and ``status_raw``, then (with a site) :data:`RUNWAY_COLUMNS` and
:data:`GEODETIC_COLUMNS`. Compensated and coordinate values are ``None``
(per frame) or NaN (batch) when the sample is NG (RX_GOOD = 0).
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterable, Iterator
from typing import Any

import construct as cs
import numpy as np

from radar_io.decoding.biases import Calibration
from radar_io.framing.framers import BatchFramer, field_raw
from radar_io.coordinates.transforms import Site, geodetic, runway_xyh
from radar_io.wirespec.frame import FieldSpec, FrameSpec, load_spec

DECODE_COLUMNS: tuple[str, ...] = (
    "seq", "tod_s", "sr_m", "dsr_m", "el_deg", "del_deg", "az_deg", "daz_deg",
    "go", "rx_good", "sync", "sr_c_m", "el_c_deg", "az_c_deg", "x_m", "y_m", "h_m",
)
RUNWAY_COLUMNS: tuple[str, ...] = ("xr_m", "yr_m", "hr_m")
GEODETIC_COLUMNS: tuple[str, ...] = ("lat_deg", "lon_deg", "hae_m")
#: columns that are empty (None / NaN) for an NG sample
POSITION_COLUMNS: tuple[str, ...] = ("sr_c_m", "el_c_deg", "az_c_deg", "x_m", "y_m", "h_m",
                                     *RUNWAY_COLUMNS, *GEODETIC_COLUMNS)
_INT_UNITS = ("count", "bits")
#: the words each compensated quantity is built from (main word, servo-error word)
_PAIRS = {"sr": ("sr", "dsr"), "el": ("el", "del"), "az": ("az", "daz")}


def output_columns(spec: FrameSpec, site: Site | None = None) -> tuple[str, ...]:
    """All columns a decoder built from ``spec`` (and ``site``) produces, in output order."""
    fixed = set(DECODE_COLUMNS)
    extra = [f.name for f in spec.flags if f.name not in fixed]
    extra += [f.column for f in spec.fields if f.column not in fixed]
    cols = [*DECODE_COLUMNS, *extra]
    if site is not None:
        cols += [*RUNWAY_COLUMNS, *GEODETIC_COLUMNS]
    return tuple(cols)


def _check_columns(spec: FrameSpec) -> dict[str, str]:
    """Map word name → its column, checking the spec names the columns the outputs require."""
    col = {f.name: f.column for f in spec.fields}
    want = {"seq": "seq", "tod": "tod_s", "sr": "sr_m", "dsr": "dsr_m", "el": "el_deg",
            "del": "del_deg", "az": "az_deg", "daz": "daz_deg"}
    from radar_io.errors import SpecError

    for name, column in want.items():
        if col.get(name) != column:
            raise SpecError(f"{spec.path}: field {name!r} must have column = {column!r}")
    return col


def construct_struct(spec: FrameSpec) -> cs.Construct:
    """A compiled construct ``Struct`` of the frame's raw words (sync, fields, crc), from the spec."""
    fmt = {1: cs.Int8ub, 2: cs.Int16ub, 4: cs.Int32ub}
    items = [(0, 2, "sync"), *((f.offset, f.size, f.name) for f in spec.fields),
             (spec.crc.offset, 2, "crc")]
    parts: list[cs.Construct] = []
    pos = 0
    for off, size, name in sorted(items):
        if off > pos:
            parts.append(cs.Padding(off - pos))
        parts.append(name / fmt[size])
        pos = off + size
    if pos < spec.length:
        parts.append(cs.Padding(spec.length - pos))
    return cs.Struct(*parts).compile()


def _compile_word_decoder(spec: FrameSpec) -> tuple[str, Any]:
    """Python source (and function) turning construct's raw words into engineering values.

    Generated from the spec, like construct's own compiler does for parsing: one line per
    field and flag, with the masks, offsets and LSBs of the spec as literals. ``source``
    is kept on the decoder for inspection.
    """
    lines = ["def decode_words(raw, m):"]
    for f in spec.fields:
        word = f"(raw[{f.name!r}] & {f.value_mask})"
        half = 1 << (f.bits - 1)
        if f.encoding == "twos_complement":
            lines.append(f"    v = {word}")
            word = f"(v - {half << 1} if v >= {half} else v)"
        elif f.encoding == "offset_binary":
            word = f"({word} - {half})"
        lines.append(f"    m[{f.column!r}] = {word}" if f.unit in _INT_UNITS
                     else f"    m[{f.column!r}] = {word} * {f.lsb!r}")
    lines.append(f"    sts = raw[{spec.status_field!r}]")
    for fl in spec.flags:
        lines.append(f"    m[{fl.name!r}] = (sts & {fl.mask}) >> {fl.shift}")
    src = "\n".join(lines) + "\n"
    ns: dict[str, Any] = {}
    exec(compile(src, f"<{spec.name} word decoder>", "exec"), ns)  # noqa: S102 - our own source
    return src, ns["decode_words"]


class FrameDecoder:
    """Per-frame decoder: ``decode(frame_bytes) -> dict`` of column → value."""

    def __init__(self, spec: FrameSpec | None = None, calibration: Calibration | None = None,
                 site: Site | None = None) -> None:
        self.spec = spec = spec or load_spec()
        self.calibration = calibration or Calibration()
        self.site = site
        self._col = _check_columns(spec)
        self.struct = construct_struct(spec)
        # construct's generated parser, called without the parse() wrapper's per-call set-up
        self._parse = self.struct.parsefunc
        self._ctx = cs.Container(_params={}, _root=None, _parsing=True, _building=False,
                                 _sizing=False, _subcons=None, _io=None, _index=None)
        self._ctx["_"] = self._ctx
        self._sts = spec.status_field
        self.columns = output_columns(spec, site)
        self._template = dict.fromkeys(self.columns)
        self.source, self._decode_words = _compile_word_decoder(spec)

    def decode(self, frame: bytes) -> dict[str, Any]:
        """Decode one accepted frame (CRC already checked by the framer)."""
        m = self._template.copy()
        self._decode_words(self._parse(io.BytesIO(frame), self._ctx), m)
        if m["rx_good"]:
            self._position(m)
        return m

    def _position(self, m: dict[str, Any]) -> None:
        cal = self.calibration
        sr = m["sr_m"] + m["dsr_m"] + cal.dsr_m
        el = m["el_deg"] + m["del_deg"] + cal.del_deg
        az = (m["az_deg"] + m["daz_deg"] + cal.daz_deg) % 360.0
        m["sr_c_m"], m["el_c_deg"], m["az_c_deg"] = sr, el, az
        elr, azr = math.radians(el), math.radians(az)
        r = sr * math.cos(elr)
        m["x_m"], m["y_m"], m["h_m"] = r * math.cos(azr), r * math.sin(azr), sr * math.sin(elr)
        if self.site is not None:
            m["xr_m"], m["yr_m"], m["hr_m"] = (float(v) for v in runway_xyh(sr, el, az, self.site))
            m["lat_deg"], m["lon_deg"], m["hae_m"] = (float(v) for v in geodetic(sr, el, az, self.site))


class MeasurementBatch:
    """Decoded measurements as numpy columns: ``batch["sr_m"]``; ``batch.stats`` holds the framer counters."""

    def __init__(self, columns: dict[str, np.ndarray], stats: dict[str, int] | None = None,
                 order: Iterable[str] | None = None) -> None:
        self._cols = columns
        self.columns: tuple[str, ...] = tuple(order) if order is not None else tuple(columns)
        self.stats: dict[str, int] = dict(stats or {})

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self._cols[name]
        except KeyError as exc:
            raise KeyError(f"no column {name!r}; columns are {', '.join(self.columns)}") from exc

    def __contains__(self, name: object) -> bool:
        return name in self._cols

    def __len__(self) -> int:
        return len(self._cols[self.columns[0]]) if self.columns else 0

    def keys(self) -> tuple[str, ...]:
        return self.columns

    def __repr__(self) -> str:
        return f"MeasurementBatch({len(self)} rows, stats={self.stats})"

    @classmethod
    def concat(cls, batches: list["MeasurementBatch"], stats: dict[str, int] | None = None
               ) -> "MeasurementBatch":
        if not batches:
            raise ValueError("no batches to concatenate")
        order = batches[0].columns
        cols = {c: np.concatenate([b[c] for b in batches]) for c in order}
        return cls(cols, stats if stats is not None else batches[-1].stats, order)


def _value_table(f: FieldSpec) -> np.ndarray:
    """Engineering value for every raw code the (plausible) word can hold, by the spec's encoding."""
    return f.counts_array(np.arange(1 << f.bits, dtype=np.int64)) * f.lsb


def _coalesce(blocks: list[np.ndarray], rows: int) -> Iterator[np.ndarray]:
    """Blocks joined into pieces of at least ``rows`` rows (a damaged stream yields many small
    blocks; decoding each alone would be mostly per-call overhead)."""
    group: list[np.ndarray] = []
    n = 0
    for b in blocks:
        if b.shape[0] >= rows and not group:
            yield b
            continue
        group.append(b)
        n += b.shape[0]
        if n >= rows:
            yield np.concatenate(group)
            group, n = [], 0
    if group:
        yield group[0] if len(group) == 1 else np.concatenate(group)


class BatchDecoder:
    """Vectorised decoder of framed words (N, L/2) → columns; the twin of :class:`FrameDecoder`."""

    def __init__(self, spec: FrameSpec | None = None, calibration: Calibration | None = None,
                 site: Site | None = None) -> None:
        self.spec = spec = spec or load_spec()
        self._col = _check_columns(spec)
        self.site = site
        self.columns = output_columns(spec, site)
        self._fields: list[tuple[FieldSpec, np.ndarray | None]] = []
        for f in spec.fields:
            small = f.size <= 2 and f.unit not in _INT_UNITS
            self._fields.append((f, _value_table(f) if small else None))
        self._value = {f.name: t for f, t in self._fields}
        sts = spec.field(spec.status_field)
        self._sts = (sts.offset, sts.size)
        self._flags = [(f.name, f.mask, f.shift) for f in spec.flags]
        self._flag_names = {f.name for f in spec.flags}
        self._int_columns = {f.column for f in spec.fields if f.unit in _INT_UNITS}
        self.set_calibration(calibration or Calibration())

    def set_calibration(self, cal: Calibration) -> None:
        """Use new biases; rebuilds the small servo-error angle tables."""
        self.calibration = cal
        self._phasor: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for q, bias in (("el", cal.del_deg), ("az", cal.daz_deg)):
            main, err = _PAIRS[q]
            tm, te = self._value.get(main), self._value.get(err)
            if tm is None or te is None:
                continue
            self._phasor[q] = (np.exp(1j * np.deg2rad(tm)), np.exp(1j * np.deg2rad(te + bias)))

    #: frames decoded per inner step; temporaries stay in the CPU cache
    BLOCK = 8192

    def decode(self, w: np.ndarray | list[np.ndarray]) -> dict[str, np.ndarray]:
        """Columns for frames given as native 16-bit words (one array or a list of blocks)."""
        blocks = [w] if isinstance(w, np.ndarray) else list(w)
        n = sum(b.shape[0] for b in blocks)
        out = {c: np.empty(n, dtype=self._dtype(c)) for c in self.columns
               if c not in RUNWAY_COLUMNS and c not in GEODETIC_COLUMNS}
        s = 0
        for blk in _coalesce(blocks, self.BLOCK):
            for k in range(0, blk.shape[0], self.BLOCK):
                sub = blk[k:k + self.BLOCK]
                self._decode_into(sub, {c: a[s:s + sub.shape[0]] for c, a in out.items()})
                s += sub.shape[0]
        if self.site is not None:
            sr, el, az = out["sr_c_m"], out["el_c_deg"], out["az_c_deg"]
            out["xr_m"], out["yr_m"], out["hr_m"] = runway_xyh(sr, el, az, self.site)
            out["lat_deg"], out["lon_deg"], out["hae_m"] = geodetic(sr, el, az, self.site)
        return out

    def _dtype(self, column: str) -> type:
        if column in self._flag_names:
            return np.uint8
        if column in self._int_columns:
            return np.int64
        return np.float64

    def _decode_into(self, w: np.ndarray, out: dict[str, np.ndarray]) -> None:
        raws: dict[str, np.ndarray] = {}
        for f, table in self._fields:
            raw = field_raw(w, f.offset, f.size)
            raws[f.name] = raw
            dst = out[f.column]
            if table is not None:
                table.take(raw, out=dst, mode="clip")
            elif f.unit in _INT_UNITS:
                dst[:] = f.counts_array(raw) if f.is_signed else raw
            else:
                np.multiply(f.counts_array(raw) if f.is_signed else raw, f.lsb, out=dst)
        sts = raws[self.spec.status_field]
        for name, mask, shift in self._flags:
            np.right_shift(sts & mask, shift, out=out[name], casting="unsafe")
        self._position(out, raws)

    def _position(self, out: dict[str, np.ndarray], raws: dict[str, np.ndarray]) -> None:
        cal = self.calibration
        ng = out["rx_good"] == 0
        sr = np.add(out["sr_m"], out["dsr_m"], out=out["sr_c_m"])
        if cal.dsr_m:
            sr += cal.dsr_m
        el = np.add(out["el_deg"], out["del_deg"], out=out["el_c_deg"])
        if cal.del_deg:
            el += cal.del_deg
        az = np.add(out["az_deg"], out["daz_deg"], out=out["az_c_deg"])
        if cal.daz_deg:
            az += cal.daz_deg
        # (az mod 360) without np.mod: exact and equal to Python's % for -360 <= az < 720
        np.subtract(az, 360.0, out=az, where=az >= 360.0)
        np.add(az, 360.0, out=az, where=az < 0.0)
        if az.size and not (0.0 <= az.min() and az.max() < 360.0):
            np.mod(az, 360.0, out=az)
        np.copyto(sr, np.nan, where=ng)
        if len(self._phasor) == 2:
            tm, te = self._phasor["el"]
            e_el = tm.take(raws["el"], mode="clip")
            e_el *= te.take(raws["del"], mode="clip")
            tm, te = self._phasor["az"]
            e_az = tm.take(raws["az"], mode="clip")
            e_az *= te.take(raws["daz"], mode="clip")
            r = sr * e_el.real
            np.multiply(sr, e_el.imag, out=out["h_m"])
            np.multiply(r, e_az.real, out=out["x_m"])
            np.multiply(r, e_az.imag, out=out["y_m"])
        else:  # spec with wide angle words: plain trigonometry
            elr, azr = np.deg2rad(el), np.deg2rad(az)
            r = sr * np.cos(elr)
            np.multiply(r, np.cos(azr), out=out["x_m"])
            np.multiply(r, np.sin(azr), out=out["y_m"])
            np.multiply(sr, np.sin(elr), out=out["h_m"])
        np.copyto(el, np.nan, where=ng)
        np.copyto(az, np.nan, where=ng)

    def batch(self, w: np.ndarray | list[np.ndarray], stats: dict[str, int] | None = None) -> MeasurementBatch:
        return MeasurementBatch(self.decode(w), stats, self.columns)


def iter_decode(chunks: Iterable[bytes], *, spec: FrameSpec | None = None,
                calibration: Calibration | None = None, site: Site | None = None,
                framer: BatchFramer | None = None) -> Iterator[MeasurementBatch]:
    """Stream byte chunks through the batch framer and decoder, one batch per chunk (and one at the end).

    Memory stays bounded by the chunk size. Each batch's ``stats`` is the
    framer's cumulative counters at that point.
    """
    spec = spec or load_spec()
    framer = framer or BatchFramer(spec)
    dec = BatchDecoder(spec, calibration, site)
    for chunk in chunks:
        blocks = framer.feed_blocks(chunk)
        if blocks:
            yield dec.batch(blocks, framer.stats.as_dict())
    framer.flush()
    yield dec.batch(np.empty((0, spec.length // 2), np.uint16), framer.stats.as_dict())


def decode_bytes(data: bytes | bytearray | memoryview, calibration: Calibration | None = None, *,
                 spec: FrameSpec | None = None, site: Site | None = None) -> MeasurementBatch:
    """Frame and decode a whole byte buffer: ``batch["sr_m"]`` … and ``batch.stats``."""
    spec = spec or load_spec()
    framer = BatchFramer(spec)
    blocks = framer.feed_blocks(data)
    framer.flush()
    dec = BatchDecoder(spec, calibration, site)
    return MeasurementBatch(dec.decode(blocks), framer.stats.as_dict(), dec.columns)
