"""The service's calibration sets on disk (``DATA_DIR/calibrations/``), kept through power cuts.

* ``NAME.json``: the newest version of each set applied with ``PUT /api/calibration``;
* ``active.json``: the set applied now, read at start;
* ``history/NAME@<UTC stamp>.json``: every version ever applied, oldest to newest by
  stamp — the history of each set and, in stamp order, of ``active.json`` too.

Every file is written through :func:`~radar_io.decoding.biases.save_calibration` (a unique
temporary name, fsync of the file, rename, fsync of the directory), and one lock orders
the writes and the live switch, so two concurrent PUTs never share a temporary file and
``active.json`` always holds the set applied last.

An ``active.json`` that cannot be read at start (empty after a power cut, truncated, not
JSON, not a calibration set) does not stop the service: it starts with no biases,
:attr:`CalibrationStore.error` says why (``/api/status`` ``calibration_error``, the
built-in alarm ``calibration_unreadable``) and :attr:`CalibrationStore.last_good` offers
the newest readable older set, to apply with ``PUT /api/calibration``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from radar_io.decoding.biases import Calibration, load_calibration, save_calibration
from radar_io.errors import ConfigError

log = logging.getLogger("radar_io.service")

ACTIVE = "active.json"
HISTORY = "history"
#: between a set's id and its stamp in a history file name (never in an id)
STAMP_SEP = "@"


def utc_stamp() -> str:
    """A UTC label for a history file name, microseconds: ``20261125T223000.123456Z``."""
    t_ns = time.time_ns()  # a label, not a duration
    return time.strftime("%Y%m%dT%H%M%S", time.gmtime(t_ns // 1_000_000_000)) + \
        f".{t_ns // 1000 % 1_000_000:06d}Z"


class CalibrationStore:
    """``calibrations/`` of the data directory; see the module docstring."""

    def __init__(self, directory: Path) -> None:
        self.dir = Path(directory)
        self.history_dir = self.dir / HISTORY
        self.history_dir.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        #: why ``active.json`` could not be used at start (one line naming it), or None
        self.error: str | None = None
        #: the newest readable older set when ``active.json`` was unreadable:
        #: ``{"file": path, "set": document}`` (PUT ``set`` to apply it), or None
        self.last_good: dict[str, Any] | None = None

    def load_active(self) -> Calibration:
        """The set in ``active.json``; the all-zero set when there is none or it is
        unreadable (then :attr:`error` and :attr:`last_good` are set, and it is logged)."""
        path = self.dir / ACTIVE
        if not path.exists():
            return Calibration()
        try:
            return load_calibration(path)
        except ConfigError as exc:
            self.error = f"{exc}; started without calibration biases"
            self.last_good = self._newest_readable()
            log.error("%s (last good set: %s)", self.error,
                      self.last_good["file"] if self.last_good else "none")
            return Calibration()

    def save(self, cal: Calibration, apply: Callable[[Calibration], None]) -> None:
        """Keep ``cal`` (history version, ``NAME.json``, ``active.json``, each durable),
        then ``apply(cal)``; StorageError when the disk refuses (nothing applied)."""
        with self._lock:
            stem = f"{cal.id}{STAMP_SEP}{utc_stamp()}"
            version, k = self.history_dir / f"{stem}.json", 1
            while version.exists():
                version, k = self.history_dir / f"{stem}-{k}.json", k + 1
            save_calibration(cal, version)
            save_calibration(cal, self.dir / f"{cal.id}.json")
            save_calibration(cal, self.dir / ACTIVE)
            apply(cal)
            self.error, self.last_good = None, None

    def history(self) -> list[Path]:
        """The history files, newest first (by their stamp)."""
        files = [p for p in self.history_dir.glob(f"*{STAMP_SEP}*.json") if p.is_file()]
        return sorted(files, key=lambda p: p.name.rsplit(STAMP_SEP, 1)[1], reverse=True)

    def _newest_readable(self) -> dict[str, Any] | None:
        """The newest history version that loads, else the newest readable ``NAME.json``."""
        sets = [p for p in self.dir.glob("*.json") if p.name != ACTIVE and p.is_file()]
        sets.sort(key=lambda p: p.stat().st_mtime, reverse=True)
        for p in self.history() + sets:
            try:
                cal = load_calibration(p)
            except ConfigError:
                continue
            return {"file": str(p), "set": cal.to_dict()}
        return None
