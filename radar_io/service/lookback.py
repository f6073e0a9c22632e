"""Look-back indexes in the service: one :class:`~radar_io.analysis.series.SeriesIndex` per
recording, decoded with the live calibration, site and reference path.

An index is made on the first query, or when a recording closes (``Recorder.on_closed``:
:meth:`LookBack.submit`, built by one worker thread, off the reader thread); a recording
still being written is indexed up to its last whole chunk (``committed_bytes``) and
extended at each query. The index never takes the last ``low_space_mb`` of the disk: that
room is the live recording's.
"""

from __future__ import annotations

import logging
import queue
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from radar_io.analysis.series import SeriesIndex, SeriesOptions

if TYPE_CHECKING:
    from radar_io.service.state import ServiceState

log = logging.getLogger("radar_io.series")


class LookBack:
    """Indexes of the service's recordings, and the worker that builds them on close."""

    def __init__(self, state: "ServiceState") -> None:
        self.state = state
        self.built = 0
        self.errors = 0
        self.last_error: str | None = None
        self._q: queue.Queue[Path | None] = queue.Queue()
        self._thread: threading.Thread | None = None

    def options(self) -> SeriesOptions:
        """Spec, the calibration live now, site and reference path of the service."""
        s = self.state
        return SeriesOptions(s.spec, s.acq.calibration, s.site, s.path)

    def index(self, rec_id: str) -> tuple[SeriesIndex, int | None]:
        """The index of a recording (NotFoundError / ValidationError for a bad id) and how far
        to read it: the committed bytes of the open recording, None (all) for a closed one."""
        path = self.state.recording_path(rec_id)
        idx = SeriesIndex(path, self.options(), reserve_bytes=self.state.recorder.low_space_bytes)
        return idx, self.state.recorder.committed_bytes(rec_id)

    # -- built when a recording closes -----------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="series-index", daemon=True)
        self._thread.start()

    def submit(self, path: Path) -> None:
        """A recording that has just closed (any thread; never blocks)."""
        if self._thread is not None:
            self._q.put_nowait(path)

    def _run(self) -> None:
        while (path := self._q.get()) is not None:
            try:
                SeriesIndex(path, self.options(),
                            reserve_bytes=self.state.recorder.low_space_bytes).update()
                self.built += 1
            except Exception as exc:  # noqa: BLE001 - a failed index never stops the next
                self.errors += 1
                self.last_error = f"{path.name}: {exc}"
                log.warning("look-back index of %s failed: %s", path.name, exc)

    def stats(self) -> dict[str, Any]:
        return {"built": self.built, "errors": self.errors, "pending": self._q.qsize(),
                "last_error": self.last_error}

    def close(self, timeout_s: float = 30.0) -> None:
        """Finish the index being built (up to ``timeout_s``); drop the queued ones (they are
        built on their first query)."""
        if self._thread is None:
            return
        while True:
            try:
                self._q.get_nowait()
            except queue.Empty:
                break
        self._q.put_nowait(None)
        self._thread.join(timeout_s)
