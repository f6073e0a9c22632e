"""Automatic and manual raw recording, and the index of sync (camera shutter) events.

The reader thread hands every received chunk to :meth:`Recorder.on_chunk`
*before* decoding. While no recording is open the recent chunks sit in a short
pre-roll ring, so a recording started by a GO 0→1 edge (seen only after the
chunk that holds it is decoded) still begins with that chunk and the pre-roll.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from radar_io.coordinates.transforms import Site
from radar_io.errors import RecordingError
from radar_io.recording.rdrlog import RecordingWriter
from radar_io.wirespec.frame import FrameSpec

AUTO_MODES = ("go", "manual", "always")


@dataclass
class SyncEvent:
    """A SYNC 0→1 edge: the frame's SEQ and TOD, its receive time, the open recording."""

    seq: int
    tod_s: float
    t_ns: int
    msg_seq: int
    recording: str | None

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class Recorder:
    """Opens a new ``.rdrlog`` per GO period (``auto="go"``), on request, or continuously.

    The pre-roll ring always holds the last ``preroll_s`` of chunks (and never less than
    the chunk being decoded plus one frame), so a recording opened by an edge found in
    that chunk starts before the frame that holds the edge, even when GO fell and rose
    again within one read.
    """

    def __init__(self, data_dir: Path, spec: FrameSpec, site: Site | None, source: str,
                 auto: str = "go", preroll_s: float = 2.0) -> None:
        if auto not in AUTO_MODES:
            raise ValueError(f"auto recording mode must be one of {AUTO_MODES}")
        self.dir = data_dir / "recordings"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.spec, self.site, self.source, self.auto = spec, site, source, auto
        self.preroll_s = preroll_s
        self._pre: deque[tuple[int, bytes]] = deque()
        self._pre_bytes = 0
        self._writer: RecordingWriter | None = None
        self._lock = threading.Lock()
        self._manual = False
        self.enabled = True  # False while replaying: replayed bytes are not recorded again
        self.sync_events: list[SyncEvent] = []
        self.last_error: str | None = None
        if auto == "always":
            self.start(reason="always")

    # -- called by the reader thread ---------------------------------------------------------
    def on_chunk(self, data: bytes, t_ns: int) -> None:
        """Keep the chunk in the pre-roll and append it to the open recording.

        A failing disk closes the recording (reported in ``last_error``) and raises
        RecordingError; the caller carries on decoding.
        """
        with self._lock:
            if not self.enabled:
                return
            self._pre.append((t_ns, data))
            self._pre_bytes += len(data)
            keep = len(data) + self.spec.length  # the frame in progress may start earlier
            while (len(self._pre) > 1 and t_ns - self._pre[0][0] > self.preroll_s * 1e9
                   and self._pre_bytes - len(self._pre[0][1]) >= keep):
                self._pre_bytes -= len(self._pre.popleft()[1])
            if self._writer is not None:
                try:
                    self._writer.write(data, t_ns)
                except RecordingError as exc:
                    self._fail(exc)
                    raise

    def _fail(self, exc: Exception) -> None:
        self.last_error = str(exc)
        w, self._writer = self._writer, None
        if w is not None:
            try:
                w.close()
            except (OSError, RecordingError):
                pass

    def on_go_edge(self, rising: bool) -> None:
        if self.auto != "go" or self._manual or not self.enabled:
            return
        if rising and self._writer is None:
            self.start(reason="go")
        elif not rising and self._writer is not None:
            self.stop()

    def on_sync(self, ev: SyncEvent) -> None:
        """Index a sync event (``ev.recording``: the recording that holds its frame)."""
        with self._lock:
            self.sync_events.append(ev)
            if len(self.sync_events) > 100_000:
                del self.sync_events[:10_000]
        if ev.recording is not None:
            try:
                with open(self.dir / f"{ev.recording}.sync.jsonl", "a", encoding="utf-8") as f:
                    f.write(json.dumps(ev.as_dict()) + "\n")
            except OSError as exc:
                self.last_error = f"cannot write the sync index of {ev.recording}: {exc.strerror}"

    # -- control ---------------------------------------------------------------------------
    def start(self, reason: str = "manual") -> str:
        """Open a new recording (with the pre-roll); returns its id. No-op if one is open."""
        with self._lock:
            if self._writer is None:
                stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
                path = self.dir / f"{stamp}.rdrlog"
                k = 1
                while path.exists():
                    path = self.dir / f"{stamp}-{k}.rdrlog"
                    k += 1
                writer = RecordingWriter(path, self.spec, site=self.site, source=self.source,
                                         extra={"started_by": reason})
                for t, d in self._pre:
                    writer.write(d, t)
                self._writer = writer
                self.last_error = None
            if reason == "manual":
                self._manual = True  # a GO fall no longer ends it
            return self._writer.path.stem

    def stop(self) -> str | None:
        with self._lock:
            self._manual = False
            w, self._writer = self._writer, None
            if w is None:
                return None
            w.close()
            return w.path.stem

    def resume_live(self) -> None:
        """Back from a replay: recording is enabled again (and restarts in ``always`` mode)."""
        self.enabled = True
        with self._lock:
            self._pre.clear()
            self._pre_bytes = 0
        if self.auto == "always":
            self.start(reason="always")

    @property
    def current(self) -> str | None:
        w = self._writer
        return w.path.stem if w is not None else None

    def close(self) -> None:
        self.stop()
