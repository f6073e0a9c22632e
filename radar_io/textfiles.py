"""Reading the project's small text documents (TOML specs, sites, paths, configs; JSON sets)
with one clear error naming the file and the problem, raised as the caller's error type."""

from __future__ import annotations

import json
import os
import tomllib
from pathlib import Path
from typing import Any, BinaryIO

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
              error: type[RadarIOError] = ConfigError) -> dict[str, Any]:
    """A TOML document as a dict."""
    return parse_toml(*read_text(path, what, error), what, error)


def parse_toml(p: Path, raw: bytes, what: str,
               error: type[RadarIOError] = ConfigError) -> dict[str, Any]:
    try:
        return tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{what} {p} is not valid TOML: {exc}") from exc


def read_json(path: str | os.PathLike[str], what: str,
              error: type[RadarIOError] = ConfigError) -> Any:
    """A JSON document."""
    p, raw = read_text(path, what, error)
    try:
        return json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise error(f"{what} {p} is not UTF-8 text: {exc}") from exc
    except json.JSONDecodeError as exc:
        raise error(f"{what} {p} is not valid JSON: {exc.msg} (line {exc.lineno})") from exc
