"""Per-frame decoder: one accepted frame → dict of column → value (live use, debugging).

The frame is unpacked by a ``struct.Struct`` compiled from the spec (pad bytes
for gaps, ``B``/``H``/``I`` big-endian words); the words → units step is
Python source generated from the spec (one line per field and flag, masks and
LSBs as literals), then compensation and coordinates follow the
:class:`~radar_io.decoding.model.DecodeModel` description.
"""

from __future__ import annotations

import math
import struct
from typing import Any

from radar_io.coordinates.transforms import Site, geodetic, runway_xyh
from radar_io.decoding.biases import Calibration
from radar_io.decoding.model import DecodeModel
from radar_io.wirespec.frame import FrameSpec

_CODES = {1: "B", 2: "H", 4: "I"}


def frame_items(spec: FrameSpec) -> list[tuple[int, int, str]]:
    """(offset, size, name) of every word of the frame: sync, the fields, crc — in offset order."""
    return sorted([(0, 2, "sync"), *((f.offset, f.size, f.name) for f in spec.fields),
                   (spec.crc.offset, 2, "crc")])


def frame_struct(spec: FrameSpec) -> tuple[struct.Struct, tuple[str, ...]]:
    """A ``struct.Struct`` unpacking a whole frame into its words, and the words' names in order."""
    fmt, pos, names = ">", 0, []
    for off, size, name in frame_items(spec):
        if off > pos:
            fmt += f"{off - pos}x"
        fmt += _CODES[size]
        names.append(name)
        pos = off + size
    if pos < spec.length:
        fmt += f"{spec.length - pos}x"
    return struct.Struct(fmt), tuple(names)


def construct_struct(spec: FrameSpec) -> Any:
    """A compiled construct ``Struct`` of the frame's raw words (sync, fields, crc), from the spec.

    Public construct API only (used by the RDR1 encoder to build frames)."""
    import construct as cs

    fmt = {1: cs.Int8ub, 2: cs.Int16ub, 4: cs.Int32ub}
    parts: list[Any] = []
    pos = 0
    for off, size, name in frame_items(spec):
        if off > pos:
            parts.append(cs.Padding(off - pos))
        parts.append(name / fmt[size])
        pos = off + size
    if pos < spec.length:
        parts.append(cs.Padding(spec.length - pos))
    return cs.Struct(*parts).compile()


def compile_word_decoder(model: DecodeModel, names: tuple[str, ...]) -> tuple[str, Any]:
    """Python source (and function) turning the unpacked word tuple into engineering values."""
    at = {n: i for i, n in enumerate(names)}
    lines = ["def decode_words(raw, m):"]
    for f in model.fields:
        word = f"(raw[{at[f.name]}] & {f.value_mask})"
        half = 1 << (f.bits - 1)
        if f.encoding == "twos_complement":
            lines.append(f"    v = {word}")
            word = f"(v - {half << 1} if v >= {half} else v)"
        elif f.encoding == "offset_binary":
            word = f"({word} - {half})"
        lines.append(f"    m[{f.column!r}] = {word} * {f.lsb!r}" if model.is_scaled(f)
                     else f"    m[{f.column!r}] = {word}")
    lines.append(f"    sts = raw[{at[model.status_field]}]")
    for name, mask, shift in model.flags:
        lines.append(f"    m[{name!r}] = (sts & {mask}) >> {shift}")
    src = "\n".join(lines) + "\n"
    ns: dict[str, Any] = {}
    exec(compile(src, f"<{model.spec.name} word decoder>", "exec"), ns)  # our own generated source
    return src, ns["decode_words"]


class FrameDecoder:
    """Per-frame decoder: ``decode(frame_bytes) -> dict`` of column → value."""

    def __init__(self, spec: FrameSpec | None = None, calibration: Calibration | None = None,
                 site: Site | None = None) -> None:
        self.model = model = DecodeModel(spec, calibration, site)
        self.spec, self.site = model.spec, site
        self.struct, self._names = frame_struct(model.spec)
        self._unpack = self.struct.unpack
        self.columns = model.columns
        self._template = dict.fromkeys(self.columns)
        self.source, self._decode_words = compile_word_decoder(model, self._names)

    @property
    def calibration(self) -> Calibration:
        return self.model.calibration

    @calibration.setter
    def calibration(self, cal: Calibration) -> None:
        self.model.set_calibration(cal)

    def decode(self, frame: bytes) -> dict[str, Any]:
        """Decode one accepted frame (CRC already checked by the framer)."""
        m = self._template.copy()
        self._decode_words(self._unpack(frame), m)
        if m["rx_good"]:
            self._position(m)
        return m

    def _position(self, m: dict[str, Any]) -> None:
        for c in self.model.compensations:  # §4: servo lag, then calibration bias
            v = m[c.word_column] + m[c.error_column] + c.bias
            m[c.column] = v % c.wrap if c.wrap else v
        sr, el, az = m["sr_c_m"], m["el_c_deg"], m["az_c_deg"]
        elr, azr = math.radians(el), math.radians(az)
        r = sr * math.cos(elr)
        m["x_m"], m["y_m"], m["h_m"] = r * math.cos(azr), r * math.sin(azr), sr * math.sin(elr)
        if self.site is not None:
            m["xr_m"], m["yr_m"], m["hr_m"] = (float(v) for v in runway_xyh(sr, el, az, self.site))
            m["lat_deg"], m["lon_deg"], m["hae_m"] = (float(v) for v in geodetic(sr, el, az, self.site))
