"""Archive each recording when it closes (config ``archive_dir``): one worker thread decodes
the closed ``.rdrlog`` into its partition of the campaign's Parquet dataset
(:func:`radar_io.analysis.archive.archive_recording`), off the reader thread, one recording
at a time. Failures are counted and shown on ``/api/status`` ``archive``; they never touch
acquisition or recording.
"""

from __future__ import annotations

import logging
import queue
import threading
from pathlib import Path
from typing import Any, Callable

log = logging.getLogger("radar_io.archive")


class RecordingArchiver:
    """Queue of closed recordings → Parquet partitions under ``out_dir``."""

    def __init__(self, out_dir: str | Path, options: Callable[[], dict[str, Any]]) -> None:
        self.out_dir = Path(out_dir)
        self.options = options  # () -> keyword arguments of archive_recording (site, calibration…)
        self.q: queue.Queue[Path | None] = queue.Queue()
        self.archived = 0
        self.errors = 0
        self.last: str | None = None
        self.last_error: str | None = None
        self._busy = False
        self._thread = threading.Thread(target=self._run, name="archiver", daemon=True)
        self._thread.start()

    def submit(self, path: Path) -> None:
        """A recording that has just closed (any thread; never blocks)."""
        self.q.put_nowait(path)

    def _run(self) -> None:
        from radar_io.analysis.archive import archive_recording

        while True:
            path = self.q.get()
            if path is None:
                return
            self._busy = True
            try:
                res = archive_recording(path, self.out_dir, **self.options())
                self.archived += 1
                self.last = str(res.path)
                log.info("archived %s → %s (%d rows)", path.name, res.path, res.rows)
            except Exception as exc:  # noqa: BLE001 - a failed archive never stops the next
                self.errors += 1
                self.last_error = f"{path.name}: {exc}"
                log.warning("archive of %s failed: %s", path.name, exc)
            finally:
                self._busy = False

    def stats(self) -> dict[str, Any]:
        return {"dir": str(self.out_dir), "archived": self.archived, "errors": self.errors,
                "pending": self.q.qsize() + int(self._busy), "last": self.last,
                "last_error": self.last_error}

    def close(self, timeout_s: float = 60.0) -> None:
        """Finish what is queued (up to ``timeout_s``), then stop."""
        self.q.put_nowait(None)
        self._thread.join(timeout_s)
