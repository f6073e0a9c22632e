"""CSV input for the calibration commands, with errors naming file, line and column."""

from __future__ import annotations

import csv
import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radar_io.errors import CalibrationInputError
from radar_io.textfiles import decode_text


@dataclass(frozen=True)
class Table:
    """A CSV file with a header row; blank lines and lines starting with ``#`` are skipped."""

    path: Path
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    lines: tuple[int, ...]
    sha256: str

    def __len__(self) -> int:
        return len(self.rows)

    def has(self, *names: str) -> bool:
        return all(n in self.columns for n in names)

    def require(self, *names: str) -> None:
        missing = [n for n in names if n not in self.columns]
        if missing:
            raise CalibrationInputError(
                f"{self.path}: missing column(s) {', '.join(missing)} "
                f"(found: {', '.join(self.columns) or 'none'})"
            )

    def strings(self, name: str) -> list[str]:
        self.require(name)
        i = self.columns.index(name)
        return [row[i] for row in self.rows]

    def floats(self, name: str) -> np.ndarray:
        """Column as finite floats; raises naming file, line and column on the first bad value."""
        self.require(name)
        i = self.columns.index(name)
        out = np.empty(len(self.rows))
        for k, (row, line) in enumerate(zip(self.rows, self.lines, strict=True)):
            try:
                v = float(row[i])
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                raise CalibrationInputError(
                    f"{self.path}, line {line}, column {name}: expected a finite number, got {row[i]!r}"
                )
            out[k] = v
        return out


def read_table(path: str | os.PathLike[str], *, min_rows: int = 1) -> Table:
    """Read a CSV file (UTF-8, header row, comma separated)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError as exc:
        raise CalibrationInputError(f"input file not found: {p}") from exc
    except OSError as exc:
        raise CalibrationInputError(f"cannot read {p}: {exc.strerror or exc}") from exc
    text = decode_text(p, data, "input file", CalibrationInputError)
    reader = csv.reader(text.splitlines())
    columns: tuple[str, ...] | None = None
    rows: list[tuple[str, ...]] = []
    lines: list[int] = []
    try:
        for fields in reader:
            if not fields or all(not f.strip() for f in fields) or fields[0].lstrip().startswith("#"):
                continue
            fields = [f.strip() for f in fields]
            if columns is None:
                columns = tuple(fields)
                dup = {c for c in columns if columns.count(c) > 1}
                if dup:
                    raise CalibrationInputError(
                        f"{p}, line {reader.line_num}: duplicate column(s) {', '.join(sorted(dup))}")
                continue
            if len(fields) != len(columns):
                raise CalibrationInputError(
                    f"{p}, line {reader.line_num}: expected {len(columns)} fields, got {len(fields)}"
                )
            rows.append(tuple(fields))
            lines.append(reader.line_num)
    except csv.Error as exc:
        raise CalibrationInputError(f"{p}, line {reader.line_num}: {exc}") from exc
    if columns is None:
        raise CalibrationInputError(f"{p}: empty file (expected a header row)")
    if len(rows) < min_rows:
        raise CalibrationInputError(f"{p}: expected at least {min_rows} data row(s), got {len(rows)}")
    return Table(p, columns, tuple(rows), tuple(lines), hashlib.sha256(data).hexdigest())
