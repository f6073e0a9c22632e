"""Encoders: measurements → RDR1 frame bytes, built from the same spec as the decoders.

Used by the simulator and the benchmark. :class:`FrameEncoder` builds one frame
with the construct ``Struct`` of :func:`~radar_io.decoding.decoders.construct_struct`;
:func:`encode_frames` builds many at once with numpy. Both take *raw* word
values; :func:`raw_words` turns engineering values into raw words by the spec.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from radar_io.decoding.frame_decoder import construct_struct
from radar_io.errors import EncodeError
from radar_io.wirespec.crc import crc_function, word_table
from radar_io.wirespec.frame import FieldSpec, FrameSpec, load_spec


class FrameEncoder:
    """Per-frame encoder: raw words → frame bytes (sync and CRC filled in)."""

    def __init__(self, spec: FrameSpec | None = None) -> None:
        self.spec = spec = spec or load_spec()
        self._struct = construct_struct(spec)
        self._crc = crc_function(spec.crc)
        self._names = [f.name for f in spec.fields]

    def encode_raw(self, raw: Mapping[str, int]) -> bytes:
        """Frame bytes for raw word values ``{"seq": …, "sr": …, "sts": …}``."""
        try:
            body = self._struct.build({"sync": self.spec.sync_word, "crc": 0,
                                       **{n: int(raw[n]) for n in self._names}})
        except KeyError as exc:
            raise EncodeError(f"missing raw word {exc.args[0]!r}") from exc
        except Exception as exc:  # construct's FormatFieldError etc.: value out of range
            raise EncodeError(f"cannot encode frame: {exc}") from exc
        at = self.spec.crc.offset
        return body[:at] + self._crc(body[:at]).to_bytes(2, "big") + body[at + 2:]


def field_counts(f: FieldSpec, value: np.ndarray | float, *, saturate: bool = True) -> np.ndarray:
    """Signed LSB counts for engineering values (rounded to nearest; saturated or EncodeError)."""
    counts = np.rint(np.asarray(value, dtype=np.float64) / f.lsb)
    lo, hi = f.count_range()
    if saturate:
        return np.clip(counts, lo, hi).astype(np.int64)
    if np.any((counts < lo) | (counts > hi)):
        raise EncodeError(f"{f.name}: value outside the representable range "
                          f"{lo * f.lsb} .. {hi * f.lsb} {f.unit}")
    return counts.astype(np.int64)


def counts_to_raw(f: FieldSpec, counts: np.ndarray) -> np.ndarray:
    """Raw wire words for signed counts (vectorised FieldSpec.counts_to_raw)."""
    c = np.asarray(counts, dtype=np.int64)
    if f.encoding == "offset_binary":
        return c + (1 << (f.bits - 1))
    return c & f.value_mask


def raw_words(spec: FrameSpec, values: Mapping[str, np.ndarray | float]) -> dict[str, np.ndarray]:
    """Raw words from engineering values keyed by column name (``sr_m``, ``el_deg`` …).

    ``seq`` and ``status_raw`` (unit count/bits) are taken as raw integers.
    """
    out: dict[str, np.ndarray] = {}
    for f in spec.fields:
        if f.column not in values:
            raise EncodeError(f"missing value for {f.column!r}")
        v = values[f.column]
        if f.unit in ("count", "bits"):
            out[f.name] = np.asarray(v, dtype=np.int64) & ((1 << (8 * f.size)) - 1)
        else:
            out[f.name] = counts_to_raw(f, field_counts(f, v))
    return out


def encode_frames(spec: FrameSpec, raw: Mapping[str, np.ndarray]) -> bytes:
    """Many frames at once: raw words (arrays of equal length) → concatenated frame bytes."""
    n = len(np.atleast_1d(raw[spec.fields[0].name]))
    L = spec.length
    b = np.zeros((n, L), dtype=np.uint8)
    b[:, 0] = spec.sync_word >> 8
    b[:, 1] = spec.sync_word & 0xFF
    for f in spec.fields:
        v = np.broadcast_to(np.asarray(raw[f.name], dtype=np.uint64), (n,))
        for i in range(f.size):
            b[:, f.offset + i] = (v >> np.uint64(8 * (f.size - 1 - i))) & np.uint64(0xFF)
    w = b.view(">u2").astype(np.uint16)
    t = word_table(spec.crc.poly)
    reg = np.full(n, spec.crc.init, dtype=np.uint16)
    for k in range(spec.crc.offset // 2):
        reg = t.take(reg ^ w[:, k])
    reg ^= np.uint16(spec.crc.xor_out)
    b[:, spec.crc.offset] = reg >> 8
    b[:, spec.crc.offset + 1] = reg & 0xFF
    return b.tobytes()
