"""Archive each recording when it closes (config ``archive_dir``): one worker thread decodes
the closed ``.rdrlog`` into its partition of the campaign's Parquet dataset
(:func:`radar_io.analysis.archive.archive_recording`), off the reader thread, one recording
at a time. Failures are counted and shown on ``/api/status`` ``archive``; they never touch
acquisition or recording.

Nothing is lost across a stop: at start the worker first removes the temporary ``.part``
files an interrupted archive left in the dataset, then archives every recording of the
data directory that has no partition yet (oldest first: those still queued or half done
when the service last stopped, and any made while archiving was off), then the
recordings that close from then on. At a stop it finishes the recording in hand within the
time it is given and leaves the rest for the next start.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections import deque
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

log = logging.getLogger("radar_io.archive")


def archived_stems(out_dir: Path) -> set[str]:
    """Partition values of the recordings that have a finished file in the archive."""
    from radar_io.analysis.archive import PART_NAME

    return {p.parent.name.split("=", 1)[1]
            for p in out_dir.glob(f"site=*/date=*/recording=*/{PART_NAME}")}


def remove_stale_parts(out_dir: Path) -> int:
    """Delete the temporary files of archives that never finished; how many there were."""
    from radar_io.sinks.atomic import PART_SUFFIX

    n = 0
    for p in out_dir.glob(f"site=*/date=*/recording=*/.*{PART_SUFFIX}"):
        try:
            p.unlink()
            n += 1
        except OSError as exc:
            log.warning("cannot remove the stale archive file %s: %s", p, exc.strerror)
    return n


class RecordingArchiver:
    """Queue of closed recordings → Parquet partitions under ``out_dir``."""

    def __init__(self, out_dir: str | Path, options: Callable[[], dict[str, Any]],
                 backlog: Iterable[Path] = ()) -> None:
        """``backlog``: closed recordings to archive first unless their partition exists
        (at start: the data directory's recordings, listed before any can open)."""
        self.out_dir = Path(out_dir)
        self.options = options  # () -> keyword arguments of archive_recording (site, calibration…)
        self.q: queue.Queue[Path | None] = queue.Queue()
        self.archived = 0
        self.errors = 0
        self.resumed = 0       #: backlog recordings archived at start
        self.stale_parts = 0   #: unfinished archive files removed at start
        self.last: str | None = None
        self.last_error: str | None = None
        self._backlog = deque(sorted(backlog))  # names are UTC stamps: oldest first
        self._busy = False
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._run, name="archiver", daemon=True)
        self._thread.start()

    def submit(self, path: Path) -> None:
        """A recording that has just closed (any thread; never blocks)."""
        self.q.put_nowait(path)

    def _run(self) -> None:
        self.stale_parts = remove_stale_parts(self.out_dir)
        if self.stale_parts:
            log.info("removed %d unfinished archive file(s) from %s", self.stale_parts,
                     self.out_dir)
        from radar_io.analysis.archive import partition_value

        done = archived_stems(self.out_dir)
        self._backlog = deque(p for p in self._backlog if partition_value(p.stem) not in done)
        while self._backlog and not self._closing.is_set():
            if self._archive(self._backlog.popleft()):
                self.resumed += 1
        while True:
            path = self.q.get()
            if path is None or self._closing.is_set():
                return
            self._archive(path)

    def _archive(self, path: Path) -> bool:
        from radar_io.analysis.archive import archive_recording

        self._busy = True
        try:
            res = archive_recording(path, self.out_dir, **self.options())
            self.archived += 1
            self.last = str(res.path)
            log.info("archived %s → %s (%d rows)", path.name, res.path, res.rows)
            return True
        except Exception as exc:  # noqa: BLE001 - a failed archive never stops the next
            self.errors += 1
            self.last_error = f"{path.name}: {exc}"
            log.warning("archive of %s failed: %s", path.name, exc)
            return False
        finally:
            self._busy = False

    def stats(self) -> dict[str, Any]:
        return {"dir": str(self.out_dir), "archived": self.archived, "errors": self.errors,
                "pending": len(self._backlog) + self.q.qsize() + int(self._busy),
                "resumed": self.resumed, "stale_parts_removed": self.stale_parts,
                "last": self.last, "last_error": self.last_error}

    def close(self, timeout_s: float = 60.0) -> None:
        """Stop: the recording in hand may finish within ``timeout_s``; what is still queued
        is archived at the next start."""
        self._closing.set()
        self.q.put_nowait(None)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.warning("archive still running after %g s: left for the next start", timeout_s)
