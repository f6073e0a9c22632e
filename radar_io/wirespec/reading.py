"""Small helpers to read the uplink TOML declarations (tlm1.toml, da_words.toml) strictly."""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path
from typing import Any

from radar_io.errors import SpecError
from radar_io.textfiles import parse_toml, read_text
from radar_io.wirespec.frame import ALLOWED_KEYS, CrcSpec, check_keys, eval_number, spec_dir


def read_toml(path: str | os.PathLike[str] | None, default_name: str) -> tuple[dict[str, Any], str, str]:
    """(document, path, sha256) of a spec file; default ``firmware_specs/<default_name>``."""
    p, raw = read_text(Path(path) if path is not None else spec_dir() / default_name,
                       "spec file", SpecError)
    return parse_toml(p, raw, "spec file", SpecError), str(p), hashlib.sha256(raw).hexdigest()


def req(table: dict[str, Any], key: str, typ: type | tuple[type, ...], where: str) -> Any:
    """``table[key]`` checked against ``typ`` (bool is never accepted for a number)."""
    if key not in table:
        raise SpecError(f"{where}: missing key {key!r}")
    v = table[key]
    types = typ if isinstance(typ, tuple) else (typ,)
    if not isinstance(v, types) or (isinstance(v, bool) and bool not in types):
        raise SpecError(f"{where}: key {key!r} has the wrong type ({v!r})")
    return v


def positive(table: dict[str, Any], key: str, where: str, default: Any = None) -> float:
    """A positive finite number (or arithmetic expression) from ``table``."""
    if key not in table and default is not None:
        return float(default)
    v = eval_number(req(table, key, (int, float, str), where), what=f"{where} {key}")
    if not (math.isfinite(v) and v > 0):
        raise SpecError(f"{where}: {key} must be a positive finite number")
    return v


def keys(table: dict[str, Any], allowed: str, where: str) -> None:
    """SpecError on a key of ``table`` not among the space-separated ``allowed`` names."""
    check_keys(table, frozenset(allowed.split()), where)


def tables(doc: dict[str, Any], key: str, where: str) -> list[dict[str, Any]]:
    v = doc.get(key)
    if not isinstance(v, list) or not v or not all(isinstance(t, dict) for t in v):
        raise SpecError(f"{where}: expected one or more [[{key}]] tables")
    return v


def crc_spec(doc: dict[str, Any], path: str) -> CrcSpec:
    """The [crc] table, verified against its check value of b"123456789"."""
    from radar_io.wirespec.crc import crc_function

    c = req(doc, "crc", dict, path)
    where = f"{path} [crc]"
    check_keys(c, ALLOWED_KEYS["crc"], where)
    crc = CrcSpec(
        name=str(c.get("name", "crc")),
        width=req(c, "width", int, where), poly=req(c, "poly", int, where),
        init=req(c, "init", int, where), reflect_in=req(c, "reflect_in", bool, where),
        reflect_out=req(c, "reflect_out", bool, where), xor_out=req(c, "xor_out", int, where),
        check=req(c, "check", int, where), offset=req(c, "offset", int, where),
    )
    if crc.width != 16 or crc.reflect_in or crc.reflect_out:
        raise SpecError(f"{where}: only non-reflected 16-bit CRCs are supported")
    got = crc_function(crc)(b"123456789")
    if got != crc.check:
        raise SpecError(f"{where}: check value of b'123456789' is 0x{got:04X}, "
                        f"the file says 0x{crc.check:04X}")
    return crc
