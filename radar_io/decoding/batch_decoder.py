"""Batch decoding with numpy: framed words → columns, whole buffers and streams, in fixed blocks.

:class:`BatchDecoder` evaluates the :class:`~radar_io.decoding.model.DecodeModel`
description over (N, L/2) arrays of frame words. Word → value tables hold the
value of every raw code (built from the spec's encoding), and coordinates use
exact float64 cos/sin phasor tables of every quantised angle, combined with the
angle-sum identity (no per-sample trigonometry, no float32 shortcut).

Chunked API:

* :func:`decode_bytes` frames and decodes a buffer ``block_frames`` frames at a
  time, writing into output columns allocated once (pages never touched cost
  nothing); temporaries are per inner step of :attr:`BatchDecoder.BLOCK` frames
  and stay in the CPU cache;
* :func:`iter_decode` does the same for a stream (bytes, a file, a path or an
  iterable of byte chunks) and yields :class:`MeasurementBatch` es of at most
  ``block_frames`` rows (the last one, often empty, carrying the final
  counters) — memory does not grow with the input. The framer's state carries
  across blocks and chunks: no frame is lost or doubled at a boundary.
"""

from __future__ import annotations

import mmap
import os
from collections.abc import Iterator
from functools import lru_cache
from typing import IO, Any

import numpy as np

from radar_io.coordinates.transforms import Site, geodetic, runway_xyh
from radar_io.decoding.biases import Calibration
from radar_io.decoding.measurement import MeasurementBatch
from radar_io.decoding.model import GEODETIC_COLUMNS, RUNWAY_COLUMNS, DecodeModel, value_table
from radar_io.errors import ConfigError
from radar_io.framing.core import BatchFramer, field_raw
from radar_io.wirespec.frame import FieldSpec, FrameSpec, load_spec

#: frames per block of the chunked paths (64 k frames = 1.5 MiB of RDR1)
BLOCK_FRAMES = 1 << 16


@lru_cache(maxsize=64)
def _table(f: FieldSpec) -> np.ndarray:
    return value_table(f)


@lru_cache(maxsize=64)
def _phasor(f: FieldSpec, bias: float) -> np.ndarray:
    """exp(i·(value + bias)) in radians, for every raw code of an angle word."""
    return np.exp(1j * np.deg2rad(_table(f) + bias))


#: columns at least this large come from an anonymous mmap (see :func:`column_array`)
MMAP_BYTES = 1 << 20
#: ``MADV_POPULATE_WRITE`` (linux/mman.h, Linux >= 5.14); ``mmap`` exports it from Python 3.12 on
MADV_POPULATE_WRITE = getattr(mmap, "MADV_POPULATE_WRITE", 23)
ALLOC_MODES = ("numpy", "mmap", "populate", "huge", "huge_populate")
#: how large columns get their memory (:func:`column_array`); ``RADAR_IO_COLUMN_ALLOC``
#: overrides it. 4 KiB pages by default: steady on the shared VM, where huge pages were
#: 1.6x faster in most runs but 3-5x slower in others (figures in docs/decoding.md)
COLUMN_ALLOC = os.environ.get("RADAR_IO_COLUMN_ALLOC", "mmap")


def column_array(n: int, dtype: Any, mode: str | None = None) -> np.ndarray:
    """An uninitialised 1-D column of ``n`` items; large ones in their own anonymous mmap.

    ``mode`` (default :data:`COLUMN_ALLOC`): ``numpy`` (``np.empty``), ``mmap`` (4 KiB
    pages, one fault each on first write), ``populate`` (``MAP_POPULATE``: faulted in by
    the kernel at ``mmap``), ``huge`` (``MADV_HUGEPAGE``: one fault per 2 MiB),
    ``huge_populate`` (``MADV_HUGEPAGE`` then ``MADV_POPULATE_WRITE``: the whole column
    faulted in by one call). Advice the kernel refuses is skipped (the mapping still
    works with 4 KiB pages). The mapping is released with the array. Figures in
    docs/decoding.md.
    """
    mode = mode or COLUMN_ALLOC
    if mode not in ALLOC_MODES:
        raise ConfigError(f"column allocation mode {mode!r} (RADAR_IO_COLUMN_ALLOC): "
                          f"one of {', '.join(ALLOC_MODES)}")
    dt = np.dtype(dtype)
    nbytes = n * dt.itemsize
    if mode == "numpy" or nbytes < MMAP_BYTES or not hasattr(mmap, "MAP_ANONYMOUS"):
        return np.empty(n, dtype=dt)
    flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
    if mode == "populate":
        flags |= getattr(mmap, "MAP_POPULATE", 0)
    buf = mmap.mmap(-1, nbytes, flags=flags)
    advice = {"huge": ("MADV_HUGEPAGE",), "huge_populate": ("MADV_HUGEPAGE", "POPULATE_WRITE")}
    for name in advice.get(mode, ()):
        opt = MADV_POPULATE_WRITE if name == "POPULATE_WRITE" else getattr(mmap, name, None)
        if opt is None or not hasattr(buf, "madvise"):
            continue
        try:
            buf.madvise(opt)
        except OSError:   # kernel without THP or MADV_POPULATE_WRITE: 4 KiB faults on write
            pass
    return np.frombuffer(buf, dtype=dt, count=n)


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
    """Vectorised decoder of framed words (N, L/2) → columns; the twin of ``FrameDecoder``."""

    #: frames decoded per inner step; temporaries stay in the CPU cache (8 192 → 16 384 cut
    #: the per-call overhead: decoding 0.040 → 0.033 s user for 2 M frames; 32 768 faults)
    BLOCK = 16384

    def __init__(self, spec: FrameSpec | None = None, calibration: Calibration | None = None,
                 site: Site | None = None) -> None:
        self.model = model = DecodeModel(spec, calibration, site)
        self.spec, self.site, self.columns = model.spec, site, model.columns
        self._fields: list[tuple[FieldSpec, np.ndarray | None]] = []
        for f in model.fields:
            small = f.size <= 2 and model.is_scaled(f)
            self._fields.append((f, _table(f) if small else None))
        self._by_name = {f.name: (f, t) for f, t in self._fields}
        self.set_calibration(model.calibration)

    @property
    def calibration(self) -> Calibration:
        return self.model.calibration

    def set_calibration(self, cal: Calibration) -> None:
        """Use new biases; rebuilds the small servo-error phasor tables."""
        self.model.set_calibration(cal)
        comp = {c.column: c for c in self.model.compensations}
        self._phasors: tuple[np.ndarray, ...] | None = None
        el, az = comp["el_c_deg"], comp["az_c_deg"]
        words = [self._by_name[n] for n in (el.word, el.error, az.word, az.error)]
        if all(t is not None for _, t in words):
            (fe, _), (fde, _), (fa, _), (fda, _) = words
            self._phasors = (_phasor(fe, 0.0), _phasor(fde, el.bias),
                             _phasor(fa, 0.0), _phasor(fda, az.bias))

    def _dtype(self, column: str) -> type:
        return self.model.dtype(column)

    def allocate(self, n: int) -> dict[str, np.ndarray]:
        """Output columns for ``n`` frames; pages cost nothing until written."""
        return {c: column_array(n, self._dtype(c)) for c in self.columns}

    def decode(self, w: np.ndarray | list[np.ndarray]) -> dict[str, np.ndarray]:
        """Columns for frames given as native 16-bit words (one array or a list of blocks)."""
        blocks = [w] if isinstance(w, np.ndarray) else list(w)
        out = self.allocate(sum(b.shape[0] for b in blocks))
        self.decode_into(blocks, out, 0)
        return out

    def decode_into(self, blocks: list[np.ndarray], out: dict[str, np.ndarray], start: int) -> int:
        """Decode word blocks into ``out[c][start:…]``; return the row after the last one written."""
        s = start
        for blk in _coalesce(blocks, self.BLOCK):
            for k in range(0, blk.shape[0], self.BLOCK):
                sub = blk[k:k + self.BLOCK]
                m = sub.shape[0]
                self._decode_block(sub, {c: a[s:s + m] for c, a in out.items()})
                s += m
        return s

    def _decode_block(self, w: np.ndarray, out: dict[str, np.ndarray]) -> None:
        raws: dict[str, np.ndarray] = {}
        for f, table in self._fields:
            raw = field_raw(w, f.offset, f.size)
            raws[f.name] = raw
            dst = out[f.column]
            if table is not None:
                table.take(raw, out=dst, mode="clip")
            elif not self.model.is_scaled(f):
                dst[:] = f.counts_array(raw) if f.is_signed else raw
            else:
                np.multiply(f.counts_array(raw) if f.is_signed else raw, f.lsb, out=dst)
        sts = raws[self.model.status_field]
        for name, mask, shift in self.model.flags:
            np.right_shift(sts & mask, shift, out=out[name], casting="unsafe")
        self._position(out, raws)
        if self.site is not None:
            sr, el, az = out["sr_c_m"], out["el_c_deg"], out["az_c_deg"]
            for col, v in zip(RUNWAY_COLUMNS, runway_xyh(sr, el, az, self.site), strict=True):
                out[col][:] = v
            for col, v in zip(GEODETIC_COLUMNS, geodetic(sr, el, az, self.site), strict=True):
                out[col][:] = v

    def _position(self, out: dict[str, np.ndarray], raws: dict[str, np.ndarray]) -> None:
        ng = out["rx_good"] == 0
        for c in self.model.compensations:  # §4: servo lag, then calibration bias
            v = np.add(out[c.word_column], out[c.error_column], out=out[c.column])
            if c.bias:
                v += c.bias
            if c.wrap:
                # (v mod wrap) without np.mod: exact and equal to Python's % for -wrap <= v < 2 wrap
                np.subtract(v, c.wrap, out=v, where=v >= c.wrap)
                np.add(v, c.wrap, out=v, where=v < 0.0)
                if v.size and not (v.min() >= 0.0 and v.max() < c.wrap):
                    np.mod(v, c.wrap, out=v)
        sr, el, az = out["sr_c_m"], out["el_c_deg"], out["az_c_deg"]
        np.copyto(sr, np.nan, where=ng)
        if self._phasors is not None:
            comp = {c.column: c for c in self.model.compensations}
            e_el_t, d_el_t, e_az_t, d_az_t = self._phasors
            # out-of-place products: numpy's in-place complex multiply of ONE element takes a
            # scalar loop that rounds differently; results must not depend on the block size
            e_el = (e_el_t.take(raws[comp["el_c_deg"].word], mode="clip")
                    * d_el_t.take(raws[comp["el_c_deg"].error], mode="clip"))
            e_az = (e_az_t.take(raws[comp["az_c_deg"].word], mode="clip")
                    * d_az_t.take(raws[comp["az_c_deg"].error], mode="clip"))
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

    def batch(self, w: np.ndarray | list[np.ndarray],
              stats: dict[str, int] | None = None) -> MeasurementBatch:
        return MeasurementBatch(self.decode(w), stats, self.columns)


def decode_bytes(data: bytes | bytearray | memoryview, calibration: Calibration | None = None, *,
                 spec: FrameSpec | None = None, site: Site | None = None,
                 block_frames: int = BLOCK_FRAMES) -> MeasurementBatch:
    """Frame and decode a whole byte buffer: ``batch["sr_m"]`` … and ``batch.stats``.

    Works through ``data`` ``block_frames`` frames at a time into columns allocated once.
    """
    spec = spec or load_spec()
    framer = BatchFramer(spec)
    dec = BatchDecoder(spec, calibration, site)
    mv = memoryview(data).cast("B")
    L = spec.length
    out = dec.allocate(len(mv) // L)   # the most frames the data can hold
    step = max(1, block_frames) * L
    s = 0
    for off in range(0, len(mv), step):
        s = dec.decode_into(framer.feed_blocks(mv[off:off + step]), out, s)
    framer.flush()
    if s < len(mv) // L:
        out = {c: a[:s] for c, a in out.items()}
    return MeasurementBatch(out, framer.stats.as_dict(), dec.columns)


def _chunks(source: Any, chunk_bytes: int) -> Iterator[bytes | memoryview]:
    """Byte chunks of a buffer, a path, a binary file or an iterable of chunks."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        mv = memoryview(source).cast("B")
        for off in range(0, len(mv), chunk_bytes):
            yield mv[off:off + chunk_bytes]
    elif isinstance(source, (str, os.PathLike)):
        with open(source, "rb") as f:
            yield from _chunks(f, chunk_bytes)
    elif hasattr(source, "read"):
        reader: IO[bytes] = source
        while chunk := reader.read(chunk_bytes):
            yield chunk
    else:
        yield from source


def iter_decode(source: Any, *, block_frames: int = BLOCK_FRAMES,
                spec: FrameSpec | None = None, calibration: Calibration | None = None,
                site: Site | None = None, framer: BatchFramer | None = None,
                decoder: BatchDecoder | None = None) -> Iterator[MeasurementBatch]:
    """Stream ``source`` through the batch framer and decoder in batches of ``block_frames`` rows.

    ``source``: bytes-like, a file path, a binary file object, or an iterable of
    byte chunks (a serial reader, stdin, ``recording.rdrlog.iter_payloads``);
    bytes, paths and files are read ``block_frames`` frames at a time. A batch
    holds at most ``block_frames`` rows; the frames of a chunk are all yielded
    before the next chunk is read (a live pipe is never held back). The last
    batch (often empty) carries the final counters, after the end-of-stream
    flush; ``batch.stats`` is the framer's cumulative counters when the batch was
    made. Memory is bounded by the block and chunk sizes.
    """
    spec = spec or (decoder.spec if decoder is not None else load_spec())
    framer = framer or BatchFramer(spec)
    dec = decoder or BatchDecoder(spec, calibration, site)
    n = max(1, int(block_frames))
    pending: list[np.ndarray] = []
    rows = 0

    def take(k: int) -> MeasurementBatch:
        nonlocal pending, rows
        out = dec.allocate(k)
        got, s = [], 0
        while s < k:
            b = pending[0]
            t = min(k - s, b.shape[0])
            got.append(b[:t])
            if t < b.shape[0]:
                pending[0] = b[t:]
            else:
                pending.pop(0)
            s += t
        rows -= k
        dec.decode_into(got, out, 0)
        return MeasurementBatch(out, framer.stats.as_dict(), dec.columns)

    for chunk in _chunks(source, n * spec.length):
        blocks = framer.feed_blocks(chunk)
        pending += blocks
        rows += sum(b.shape[0] for b in blocks)
        while rows:  # nothing waits for the next chunk: a live pipe stays live
            yield take(min(n, rows))
    framer.flush()
    yield take(rows)
