"""Look-back indexes in the service: one :class:`~radar_io.analysis.series.SeriesIndex` per
recording, decoded with the live calibration, site and reference path.

An index is made on the first query, or when a recording closes (``Recorder.on_closed``:
:meth:`LookBack.submit`, built by one worker thread, off the reader thread); a recording
still being written is indexed up to its last whole chunk (``committed_bytes``), extended
by the same worker every :attr:`LookBack.refresh_s` and at each query, so a look at a long
flight in progress never waits for a whole build. The index never takes the last
``low_space_mb`` of the disk: that room is the live recording's.
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

#: default :attr:`LookBack.refresh_s`: 10 s of a 1 kHz recording is 10 000 frames to index
REFRESH_S = 10.0


class LookBack:
    """Indexes of the service's recordings, and the worker that builds them on close."""

    def __init__(self, state: ServiceState) -> None:
        self.state = state
        self.errors = 0
        self.last_error: str | None = None
        self._q: queue.Queue[Path | None] = queue.Queue()
        self._thread: threading.Thread | None = None
        #: seconds between two extensions of the open recording's index
        self.refresh_s = REFRESH_S

    def options(self) -> SeriesOptions:
        """Spec, the calibration live now, site and reference path of the service."""
        s = self.state
        return SeriesOptions(s.spec, s.acq.calibration, s.site, s.path)

    def request(self, rec_id: str) -> dict[str, Any]:
        """The plain (picklable) arguments of a query of a recording, for
        :func:`~radar_io.analysis.series.query_series` / ``query_events``: its path
        (NotFoundError / ValidationError for a bad id), the options, how far to read it (the
        committed bytes of the open recording, None for a closed one) and the free space to
        keep."""
        return {"recording": self.state.recording_path(rec_id), "options": self.options(),
                "end": self.state.recorder.committed_bytes(rec_id),
                "reserve_bytes": self.state.recorder.low_space_bytes}

    # -- built when a recording closes -----------------------------------------------------
    def start(self) -> None:
        """Start the worker and hook it onto ``Recorder.on_closed`` (after what is already
        there, e.g. the archiver: both are called)."""
        before = self.state.recorder.on_closed

        def closed(path: Path) -> None:
            if before is not None:
                before(path)
            self.submit(path)

        self.state.recorder.on_closed = closed
        self._thread = threading.Thread(target=self._run, name="series-index", daemon=True)
        self._thread.start()

    def submit(self, path: Path) -> None:
        """A recording that has just closed (any thread; never blocks)."""
        if self._thread is not None:
            self._q.put_nowait(path)

    def _run(self) -> None:
        while True:
            try:
                path = self._q.get(timeout=self.refresh_s)
            except queue.Empty:  # extend the index of the recording being written
                rec_id = self.state.recorder.current
                if rec_id is not None:
                    self._update(self.state.recorder.dir / f"{rec_id}.rdrlog",
                                 self.state.recorder.committed_bytes(rec_id))
                continue
            if path is None:
                return
            self._update(path, None)

    def _update(self, path: Path, end: int | None) -> None:
        """Bring one index up to date; failures are counted and logged (once per message)."""
        try:
            SeriesIndex(path, self.options(),
                        reserve_bytes=self.state.recorder.low_space_bytes).update(end)
        except Exception as exc:  # noqa: BLE001 - a failed index never stops the next
            self.errors += 1
            msg = f"{path.name}: {exc}"
            if msg != self.last_error:
                log.warning("look-back index of %s", msg)
            self.last_error = msg

    def close(self, timeout_s: float = 1.0) -> None:
        """Stop the worker: the queued recordings are dropped (indexed on their first query)
        and an index being built is given ``timeout_s`` and then left to the daemon thread:
        an index is a cache, and an interrupted build or extension is found and redone by
        the next query (docs/lookback.md), so a stop never waits for one."""
        if self._thread is None:
            return
        while True:
            try:
                self._q.get_nowait()
            except queue.Empty:
                break
        self._q.put_nowait(None)
        self._thread.join(timeout_s)
