"""Load a wire-layout declaration from ``firmware_specs/`` (radar-interface.md §1–§3).

The TOML file is the single source of truth for the RDR1 frame: field offsets,
sizes, encodings, LSBs, the status bit map (source numbering, B0 = MSB) and the
CRC parameters. Decoders and encoders are *built from* the :class:`FrameSpec`
returned here; nothing about the layout is hard-coded in Python except the names
of the words the formulas of §4–§5 refer to (``sr``, ``dsr``, ``el``, ...).
"""

from __future__ import annotations

import ast
import hashlib
import math
import operator
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import numpy as np

from radar_io.errors import SpecError
from radar_io.textfiles import parse_toml, read_text

ENCODINGS = ("unsigned", "twos_complement", "offset_binary")
#: words the maths of radar-interface.md §4–§5 refers to by name
REQUIRED_FIELDS = ("seq", "tod", "sr", "dsr", "el", "del", "az", "daz", "sts")
REQUIRED_FLAGS = ("sync", "rx_good", "go")


def spec_dir() -> Path:
    """The ``firmware_specs`` directory: ``$RADAR_IO_SPEC_DIR``, else the one beside the
    package (a source checkout or editable install), else the installed copy under
    ``<prefix>/share/radar-io/``."""
    env = os.environ.get("RADAR_IO_SPEC_DIR")
    if env:
        return Path(env)
    beside = Path(__file__).resolve().parents[2] / "firmware_specs"
    if beside.is_dir():
        return beside
    return Path(sys.prefix) / "share" / "radar-io" / "firmware_specs"


_BINOPS: dict[type[ast.operator], Callable[[float, float], float]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
    ast.Div: operator.truediv, ast.Pow: operator.pow}
_UNOPS: dict[type[ast.unaryop], Callable[[float], float]] = {
    ast.USub: operator.neg, ast.UAdd: operator.pos}


def eval_number(expr: Any, *, what: str) -> float:
    """A number, or a string holding a simple arithmetic expression such as ``"180 * 2**-15"``."""
    if isinstance(expr, bool):
        raise SpecError(f"{what}: expected a number, got {expr!r}")
    if isinstance(expr, (int, float)):
        return float(expr)
    if not isinstance(expr, str):
        raise SpecError(f"{what}: expected a number or an arithmetic expression, got {expr!r}")

    def ev(node: ast.AST) -> float:
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            return float(node.value)
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            return _BINOPS[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp) and type(node.op) in _UNOPS:
            return _UNOPS[type(node.op)](ev(node.operand))
        raise SpecError(f"{what}: {expr!r} is not a simple arithmetic expression")

    try:
        return float(ev(ast.parse(expr, mode="eval")))
    except SyntaxError as exc:
        raise SpecError(f"{what}: cannot parse {expr!r}") from exc
    except (ZeroDivisionError, OverflowError) as exc:
        raise SpecError(f"{what}: {expr!r}: {exc}") from exc


@dataclass(frozen=True)
class FieldSpec:
    """One word of the frame."""

    name: str
    offset: int
    size: int
    encoding: str
    bits: int
    lsb: float
    unit: str
    column: str
    max_raw: int | None = None
    description: str = ""

    @property
    def value_mask(self) -> int:
        """Mask of the significant (right-justified) bits."""
        return (1 << self.bits) - 1

    @property
    def unused_mask(self) -> int:
        """Mask of the word's upper bits that must be zero on the wire."""
        return ((1 << (8 * self.size)) - 1) & ~self.value_mask

    @property
    def is_signed(self) -> bool:
        return self.encoding != "unsigned"

    def raw_to_counts(self, raw: int) -> int:
        """Signed count of LSBs for one raw word (scalar)."""
        v = raw & self.value_mask
        if self.encoding == "twos_complement":
            return v - (1 << self.bits) if v >> (self.bits - 1) else v
        if self.encoding == "offset_binary":
            return v - (1 << (self.bits - 1))
        return v

    def counts_array(self, raw: np.ndarray) -> np.ndarray:
        """Signed counts for an array of raw words (int64, vectorised twin of raw_to_counts)."""
        v = raw.astype(np.int64) & self.value_mask
        if self.encoding == "twos_complement":
            return v - ((v >> (self.bits - 1)) << self.bits)
        if self.encoding == "offset_binary":
            return v - (1 << (self.bits - 1))
        return v

    def decode(self, raw: int) -> float:
        """Engineering value of one raw word."""
        return self.raw_to_counts(raw) * self.lsb

    def count_range(self) -> tuple[int, int]:
        """Smallest and largest representable count."""
        if self.encoding == "unsigned":
            hi = (1 << self.bits) - 1 if self.max_raw is None else self.max_raw
            return 0, hi
        half = 1 << (self.bits - 1)
        return -half, half - 1

    def counts_to_raw(self, counts: int) -> int:
        """Raw wire word for a signed count (inverse of raw_to_counts)."""
        lo, hi = self.count_range()
        if not lo <= counts <= hi:
            raise ValueError(f"{self.name}: count {counts} outside {lo}..{hi}")
        if self.encoding == "offset_binary":
            return counts + (1 << (self.bits - 1))
        return counts & self.value_mask


@dataclass(frozen=True)
class FlagSpec:
    """A named bit group of the status word (source numbering: B0 = MSB)."""

    name: str
    bit: int
    width: int
    shift: int
    mask: int
    description: str = ""

    def extract(self, word: int) -> int:
        return (word & self.mask) >> self.shift


@dataclass(frozen=True)
class CrcSpec:
    """CRC parameters in the Rocksoft/Williams model; covers bytes 0 .. offset-1."""

    name: str
    width: int
    poly: int
    init: int
    reflect_in: bool
    reflect_out: bool
    xor_out: int
    check: int
    offset: int


@dataclass(frozen=True)
class FrameSpec:
    """A frame declaration loaded from ``firmware_specs/<name>.toml``."""

    name: str
    spec_version: str
    length: int
    byte_order: Literal["big", "little"]
    sync_word: int
    sync_offset: int
    crc: CrcSpec
    fields: tuple[FieldSpec, ...]
    status_field: str
    flags: tuple[FlagSpec, ...]
    path: str
    sha256: str

    @property
    def sync_bytes(self) -> bytes:
        return self.sync_word.to_bytes(2, self.byte_order)

    @property
    def word_dtype(self) -> str:
        return ">" if self.byte_order == "big" else "<"

    def field(self, name: str) -> FieldSpec:
        for f in self.fields:
            if f.name == name:
                return f
        raise SpecError(f"{self.path}: no field named {name!r}")

    def flag(self, name: str) -> FlagSpec:
        for f in self.flags:
            if f.name == name:
                return f
        raise SpecError(f"{self.path}: no status flag named {name!r}")


#: every key a frame spec file may hold, per table; anything else is refused (a typo is an error)
ALLOWED_KEYS: dict[str, frozenset[str]] = {
    "": frozenset({"frame", "crc", "field", "status"}),
    "frame": frozenset({"name", "spec_version", "length_bytes", "byte_order", "sync_word",
                        "sync_offset"}),
    "crc": frozenset({"name", "width", "poly", "init", "reflect_in", "reflect_out", "xor_out",
                      "check", "offset"}),
    "field": frozenset({"name", "offset", "size", "encoding", "bits", "lsb", "unit", "column",
                        "max_raw", "description"}),
    "status": frozenset({"field", "bit_numbering", "flag"}),
    "flag": frozenset({"name", "bit", "width", "description"}),
}


def check_keys(table: dict[str, Any], allowed: frozenset[str], where: str) -> None:
    """SpecError naming the first key of ``table`` that is not in ``allowed``."""
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SpecError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")


def _opt(table: dict[str, Any], key: str, typ: type | tuple[type, ...], where: str,
         default: Any) -> Any:
    """``table[key]`` checked like :func:`_req`, or ``default`` when absent."""
    return _req(table, key, typ, where) if key in table else default


def _table_list(doc: dict[str, Any], key: str, where: str) -> list[dict[str, Any]]:
    v = doc.get(key, [])
    if not isinstance(v, list) or not all(isinstance(t, dict) for t in v):
        raise SpecError(f"{where}: {key!r} must be an array of tables ([[{key}]])")
    return v


def _req(table: dict[str, Any], key: str, typ: type | tuple[type, ...], where: str) -> Any:
    if key not in table:
        raise SpecError(f"{where}: missing key {key!r}")
    v = table[key]
    if not isinstance(v, typ) or (isinstance(v, bool) and typ is not bool and bool not in
                                  (typ if isinstance(typ, tuple) else (typ,))):
        raise SpecError(f"{where}: key {key!r} has the wrong type ({v!r})")
    return v


def load_spec(path: str | os.PathLike[str] | None = None) -> FrameSpec:
    """Load and validate a frame spec; default ``firmware_specs/rdr1.toml``.

    Raises SpecError naming the file and the problem.
    """
    p = Path(path) if path is not None else spec_dir() / "rdr1.toml"
    return _load_spec_cached(str(p.resolve()), _mtime(p))


def _mtime(p: Path) -> int:
    try:
        return p.stat().st_mtime_ns
    except OSError as exc:
        raise SpecError(f"spec file not found: {p}") from exc


@lru_cache(maxsize=16)
def _load_spec_cached(path: str, _mtime_ns: int) -> FrameSpec:
    p, raw = read_text(path, "spec file", SpecError)
    doc = parse_toml(p, raw, "spec file", SpecError)
    return _build_spec(doc, path, hashlib.sha256(raw).hexdigest())


def _build_spec(doc: dict[str, Any], path: str, sha: str) -> FrameSpec:
    check_keys(doc, ALLOWED_KEYS[""], path)
    fr = _req(doc, "frame", dict, path)
    where = f"{path} [frame]"
    check_keys(fr, ALLOWED_KEYS["frame"], where)
    length = _req(fr, "length_bytes", int, where)
    if not 4 <= length <= 4096 or length % 2:
        raise SpecError(f"{where}: length_bytes must be an even number of bytes, 4 .. 4096")
    if (order := _req(fr, "byte_order", str, where)) != "big":
        raise SpecError(f"{where}: byte_order = {order!r} is not supported: the framers, "
                        "decoders and encoders read big-endian words only")
    byte_order: Literal["big"] = "big"
    sync_word = _req(fr, "sync_word", int, where)
    sync_offset = _opt(fr, "sync_offset", int, where, 0)
    for key in ("name", "spec_version"):
        _opt(fr, key, str, where, "")
    if sync_offset != 0:
        raise SpecError(f"{where}: the sync word must start the frame (sync_offset = 0)")
    if not 0 < sync_word <= 0xFFFF:
        raise SpecError(f"{where}: sync_word must be a non-zero 16-bit value")

    c = _req(doc, "crc", dict, path)
    where = f"{path} [crc]"
    check_keys(c, ALLOWED_KEYS["crc"], where)
    crc = CrcSpec(
        name=_opt(c, "name", str, where, "crc"),
        width=_req(c, "width", int, where),
        poly=_req(c, "poly", int, where),
        init=_req(c, "init", int, where),
        reflect_in=_req(c, "reflect_in", bool, where),
        reflect_out=_req(c, "reflect_out", bool, where),
        xor_out=_req(c, "xor_out", int, where),
        check=_req(c, "check", int, where),
        offset=_req(c, "offset", int, where),
    )
    if crc.width != 16 or crc.reflect_in or crc.reflect_out:
        raise SpecError(f"{where}: only non-reflected 16-bit CRCs are supported")
    if crc.offset + 2 != length:
        raise SpecError(f"{where}: the CRC word must be the last two bytes of the frame")

    fields: list[FieldSpec] = []
    owner: list[str] = [""] * length   # which word holds each byte
    owner[0:2] = ["the sync word"] * 2
    owner[crc.offset:crc.offset + 2] = ["the CRC"] * 2
    for i, f in enumerate(_table_list(doc, "field", path)):
        where = f"{path} [[field]] #{i + 1}"
        name = _req(f, "name", str, where)
        where = f"{path} field {name!r}"
        check_keys(f, ALLOWED_KEYS["field"], where)
        size = _req(f, "size", int, where)
        if size not in (1, 2, 4):
            raise SpecError(f"{where}: size must be 1, 2 or 4 bytes")
        offset = _req(f, "offset", int, where)
        if offset < 0 or offset + size > length:
            raise SpecError(f"{where}: offset {offset}+{size} lies outside the {length}-byte frame")
        taken = next((o for o in owner[offset:offset + size] if o), "")
        if taken:
            raise SpecError(f"{where}: bytes {offset}..{offset + size - 1} overlap {taken}")
        owner[offset:offset + size] = [f"field {name!r}"] * size
        enc = _req(f, "encoding", str, where)
        if enc not in ENCODINGS:
            raise SpecError(f"{where}: encoding {enc!r} is not one of {', '.join(ENCODINGS)}")
        bits = _opt(f, "bits", int, where, 8 * size)
        if not 1 <= bits <= 8 * size:
            raise SpecError(f"{where}: bits must be 1..{8 * size}")
        lsb = eval_number(_req(f, "lsb", (int, float, str), where), what=f"{where} lsb")
        if not (math.isfinite(lsb) and lsb > 0):
            raise SpecError(f"{where}: lsb must be a positive finite number")
        max_raw = _opt(f, "max_raw", int, where, None)
        if max_raw is not None and max_raw < 0:
            raise SpecError(f"{where}: max_raw must be >= 0")
        fields.append(FieldSpec(
            name=name, offset=offset, size=size, encoding=enc, bits=bits, lsb=lsb,
            unit=_opt(f, "unit", str, where, ""), column=_opt(f, "column", str, where, name),
            max_raw=max_raw, description=_opt(f, "description", str, where, ""),
        ))
    names = [f.name for f in fields]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise SpecError(f"{path} field {dup!r}: declared twice")
    missing = [n for n in REQUIRED_FIELDS if n not in names]
    if missing:
        raise SpecError(f"{path}: missing required field(s) {', '.join(missing)}")

    st = _req(doc, "status", dict, path)
    where = f"{path} [status]"
    check_keys(st, ALLOWED_KEYS["status"], where)
    status_field = _req(st, "field", str, where)
    sts = next((f for f in fields if f.name == status_field), None)
    if sts is None:
        raise SpecError(f"{where}: status field {status_field!r} is not declared")
    numbering = _opt(st, "bit_numbering", str, where, "msb0")
    if numbering not in ("msb0", "lsb0"):
        raise SpecError(f"{where}: bit_numbering must be 'msb0' (B0 = MSB) or 'lsb0'")
    nbits = 8 * sts.size
    flags: list[FlagSpec] = []
    used = 0
    for i, fl in enumerate(_table_list(st, "flag", where)):
        fw = f"{where} flag #{i + 1}"
        name = _req(fl, "name", str, fw)
        fw = f"{where} flag {name!r}"
        check_keys(fl, ALLOWED_KEYS["flag"], fw)
        bit = _req(fl, "bit", int, fw)
        width = _opt(fl, "width", int, fw, 1)
        if width < 1 or bit < 0 or bit + width > nbits:
            raise SpecError(f"{fw}: bits B{bit}..B{bit + width - 1} outside the {nbits}-bit word")
        # msb0: B0 is the MSB; a flag spans B<bit>..B<bit+width-1>, its lowest bit is B<bit+width-1>
        shift = nbits - (bit + width) if numbering == "msb0" else bit
        mask = ((1 << width) - 1) << shift
        if used & mask:
            raise SpecError(f"{fw}: overlaps another status flag")
        used |= mask
        flags.append(FlagSpec(name=name, bit=bit, width=width, shift=shift, mask=mask,
                              description=_opt(fl, "description", str, fw, "")))
    fnames = [f.name for f in flags]
    missing = [n for n in REQUIRED_FLAGS if n not in fnames]
    if missing:
        raise SpecError(f"{where}: missing required flag(s) {', '.join(missing)}")
    clash = set(fnames) & {f.column for f in fields}
    if clash or len(set(fnames)) != len(fnames):
        raise SpecError(f"{where}: flag names must be unique and differ from field columns")

    spec = FrameSpec(
        name=str(fr.get("name", Path(path).stem)),
        spec_version=str(fr.get("spec_version", "unversioned")),
        length=length, byte_order=byte_order, sync_word=sync_word, sync_offset=sync_offset,
        crc=crc, fields=tuple(sorted(fields, key=lambda f: f.offset)),
        status_field=status_field, flags=tuple(flags), path=path, sha256=sha,
    )
    from radar_io.wirespec.crc import crc_function  # local import: crc depends on this module's types

    got = crc_function(crc)(b"123456789")
    if got != crc.check:
        raise SpecError(f"{path} [crc]: check value of b'123456789' is 0x{got:04X}, "
                        f"the file says 0x{crc.check:04X}")
    return spec
