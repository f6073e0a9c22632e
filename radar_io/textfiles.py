"""Reading the project's small text documents (TOML specs, sites, paths, configs; JSON sets)
with one clear error naming the file and the problem, raised as the caller's error type."""

from __future__ import annotations

import json
import math
import os
import tomllib
from pathlib import Path
from typing import Any, BinaryIO, NoReturn

from radar_io.errors import ConfigError, RadarIOError


def open_input(path: str | os.PathLike[str], what: str,
               error: type[RadarIOError] = ConfigError) -> BinaryIO:
    """``path`` opened for binary reading; ``what`` names it in messages (``"site file"``)."""
    p = Path(path)
    try:
        return open(p, "rb")
    except FileNotFoundError as exc:
        raise error(f"{what} not found: {p}") from exc
    except IsADirectoryError as exc:
        raise error(f"{what} {p} is a directory, not a file") from exc
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror or exc}") from exc


def read_text(path: str | os.PathLike[str], what: str,
              error: type[RadarIOError] = ConfigError) -> tuple[Path, bytes]:
    """The raw bytes of ``path``, read whole (errors as :func:`open_input`)."""
    with open_input(path, what, error) as f:
        try:
            return Path(path), f.read()
        except OSError as exc:
            raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from exc


def read_toml(path: str | os.PathLike[str], what: str,
              error: type[RadarIOError] = ConfigError, *, allow_empty: bool = True) -> dict[str, Any]:
    """A TOML document as a dict."""
    return parse_toml(*read_text(path, what, error), what, error, allow_empty=allow_empty)


def decode_text(p: Path, raw: bytes, what: str, error: type[RadarIOError] = ConfigError, *,
                allow_empty: bool = True) -> str:
    """``raw`` as UTF-8 text; refuses a binary file (NUL bytes), bad UTF-8 and, unless
    ``allow_empty``, a file with nothing but whitespace, each in one line."""
    if b"\0" in raw:
        raise error(f"{what} {p} is a binary file, not text (NUL byte at offset {raw.index(0)})")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{what} {p} is not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset "
                    f"{exc.start})") from exc
    if not allow_empty and not text.strip():
        raise error(f"{what} {p} is empty")
    return text


def parse_toml(p: Path, raw: bytes, what: str,
               error: type[RadarIOError] = ConfigError, *, allow_empty: bool = True) -> dict[str, Any]:
    text = decode_text(p, raw, what, error, allow_empty=allow_empty)
    try:
        return tomllib.loads(text)
    except RecursionError as exc:
        raise error(f"{what} {p} is not usable TOML: nested too deeply") from exc
    except tomllib.TOMLDecodeError as exc:
        raise error(one_line(f"{what} {p} is not valid TOML: {exc}")) from exc


def read_json(path: str | os.PathLike[str], what: str,
              error: type[RadarIOError] = ConfigError, *, allow_empty: bool = False) -> Any:
    """A JSON document."""
    p, raw = read_text(path, what, error)
    text = decode_text(p, raw, what, error, allow_empty=allow_empty)
    try:
        return json.loads(text, parse_constant=_no_constant)
    except RecursionError as exc:
        raise error(f"{what} {p} is not usable JSON: nested too deeply") from exc
    except ValueError as exc:
        if not isinstance(exc, json.JSONDecodeError):
            raise error(f"{what} {p} is not valid JSON: {exc}") from exc
        raise error(f"{what} {p} is not valid JSON: {exc.msg} (line {exc.lineno})") from exc


def json_safe(x: Any) -> Any:
    """``x`` as plain JSON types for writing: numpy arrays and scalars as Python values,
    mapping keys as strings, NaN and ±inf as null."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if hasattr(x, "tolist"):
        return json_safe(x.tolist())
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    return x


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not allowed (JSON has no NaN or Infinity)")


# --------------------------------------------------------------------- field validation
_MISSING: Any = object()


def one_line(text: str) -> str:
    """``text`` with every run of whitespace (newlines too) folded into one space."""
    return " ".join(str(text).split())


def show(value: Any, limit: int = 40) -> str:
    """A short, one-line ``repr`` of a bad value for an error message."""
    r = one_line(repr(value))
    return r if len(r) <= limit else r[:limit - 3] + "..."


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    return f"a {type(value).__name__}"


class Fields:
    """Checked access to one table (dict) of a parsed document.

    Every failure raises ``error`` with ONE line naming the file and the field, e.g.
    ``path file p.toml: field points[2].x_m: expected a number, got 'a'``. ``where`` is the
    dotted name of this table inside the document ("" for the top level).
    """

    def __init__(self, doc: Any, file: str | os.PathLike[str], what: str,
                 error: type[RadarIOError] = ConfigError, where: str = "") -> None:
        self.file, self.what, self.error, self.where = str(file), what, error, where
        if not isinstance(doc, dict):
            self._raise(f"{'field ' + where if where else 'the document'}: expected "
                        f"{'a table' if where else 'a table of fields'}, got {_kind(doc)} {show(doc)}")
        self.doc: dict[str, Any] = doc

    # ------------------------------------------------------------------ plumbing
    def _raise(self, message: str) -> NoReturn:
        raise self.error(one_line(f"{self.what} {self.file}: {message}"))

    def name(self, key: str) -> str:
        """The dotted field name of ``key`` in this table."""
        return f"{self.where}.{key}" if self.where else key

    def fail(self, key: str, message: str) -> NoReturn:
        """Raise the loader's error for field ``key``."""
        self._raise(f"field {self.name(key)}: {message}")

    def has(self, key: str) -> bool:
        return key in self.doc

    def only(self, *allowed: str) -> None:
        """Refuse keys not in ``allowed`` (a typo must not be silently ignored)."""
        unknown = sorted(str(k) for k in self.doc if k not in allowed)
        if unknown:
            self.fail(unknown[0], f"unknown key (allowed here: {', '.join(allowed)})")

    def _get(self, key: str, default: Any) -> Any:
        if key in self.doc:
            return self.doc[key]
        if default is _MISSING:
            self.fail(key, "missing")
        return default

    # ------------------------------------------------------------------ typed getters
    def number(self, key: str, lo: float | None = None, hi: float | None = None, *,
               default: Any = _MISSING, above: float | None = None) -> float:
        """A finite number, ``lo <= v <= hi`` and ``v > above`` when given."""
        v = self._get(key, default)
        if v is default and key not in self.doc:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(key, f"expected a number, got {_kind(v)} {show(v)}")
        if not math.isfinite(v):
            self.fail(key, f"expected a finite number, got {v!r}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            self.fail(key, f"{v!r} is out of range {lo if lo is not None else '-inf'} .. "
                           f"{hi if hi is not None else 'inf'}")
        if above is not None and not v > above:
            self.fail(key, f"{v!r} must be greater than {above}")
        return float(v)

    def integer(self, key: str, lo: int | None = None, hi: int | None = None, *,
                default: Any = _MISSING) -> int:
        """A whole number (TOML/JSON integer), ``lo <= v <= hi``."""
        v = self._get(key, default)
        if v is default and key not in self.doc:
            return v
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(key, f"expected an integer, got {_kind(v)} {show(v)}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            self.fail(key, f"{v!r} is out of range {lo} .. {hi}")
        return int(v)

    def string(self, key: str, *, default: Any = _MISSING, choices: tuple[str, ...] = (),
               nonempty: bool = False) -> str:
        """A string, one of ``choices`` when given."""
        v = self._get(key, default)
        if v is default and key not in self.doc:
            return v
        if not isinstance(v, str):
            expect = " or ".join(f'"{c}"' for c in choices) if choices else "a string"
            self.fail(key, f"expected {expect}, got {_kind(v)} {show(v)}")
        if choices and v not in choices:
            self.fail(key, f"expected {' or '.join(repr(c) for c in choices)}, got {show(v)}")
        if nonempty and not v.strip():
            self.fail(key, "must not be empty")
        return v

    def table(self, key: str, *, required: bool = True) -> Fields | None:
        """The sub-table ``key`` (None when absent and not required)."""
        v = self._get(key, _MISSING if required else None)
        if v is None and key not in self.doc:
            return None
        if not isinstance(v, dict):
            self.fail(key, f"expected a table, got {_kind(v)} {show(v)}")
        return Fields(v, self.file, self.what, self.error, self.name(key))

    def mapping(self, key: str) -> dict[str, Any]:
        """A free-form sub-table (``{}`` when absent)."""
        v = self.doc.get(key, {})
        if v is None:
            return {}
        if not isinstance(v, dict):
            self.fail(key, f"expected a table, got {_kind(v)} {show(v)}")
        return dict(v)

    def tables(self, key: str, *, min_count: int = 0) -> list[Fields]:
        """An array of tables (TOML ``[[key]]`` / JSON list of objects)."""
        v = self._get(key, _MISSING if min_count else [])
        if not isinstance(v, list):
            self.fail(key, f"expected an array of tables, got {_kind(v)} {show(v)}")
        if len(v) < min_count:
            self.fail(key, f"expected at least {min_count} entries, got {len(v)}")
        out = []
        for i, item in enumerate(v):
            if not isinstance(item, dict):
                self.fail(f"{key}[{i}]", f"expected a table, got {_kind(item)} {show(item)}")
            out.append(Fields(item, self.file, self.what, self.error, f"{self.name(key)}[{i}]"))
        return out
