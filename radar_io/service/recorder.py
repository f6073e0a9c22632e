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

from ..geometry import Site
from ..recording import RecordingWriter
from ..spec import FrameSpec

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
    """Opens a new ``.rdrlog`` per GO period (``auto="go"``), on request, or continuously."""

    def __init__(self, data_dir: Path, spec: FrameSpec, site: Site | None, source: str,
                 auto: str = "go", preroll_s: float = 2.0) -> None:
        if auto not in AUTO_MODES:
            raise ValueError(f"auto recording mode must be one of {AUTO_MODES}")
        self.dir = data_dir / "recordings"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.spec, self.site, self.source, self.auto = spec, site, source, auto
        self.preroll_s = preroll_s
        self._pre: deque[tuple[int, bytes]] = deque()
        self._writer: RecordingWriter | None = None
        self._lock = threading.Lock()
        self._manual = False
        self.enabled = True  # False while replaying: replayed bytes are not recorded again
        self.sync_events: list[SyncEvent] = []
        self._sync_file: Any = None
        if auto == "always":
            self.start(reason="always")

    # -- called by the reader thread ---------------------------------------------------------
    def on_chunk(self, data: bytes, t_ns: int) -> None:
        with self._lock:
            if not self.enabled:
                return
            if self._writer is not None:
                self._writer.write(data, t_ns)
                return
            self._pre.append((t_ns, data))
            while self._pre and t_ns - self._pre[0][0] > self.preroll_s * 1e9:
                self._pre.popleft()

    def on_go_edge(self, rising: bool) -> None:
        if self.auto != "go" or self._manual or not self.enabled:
            return
        if rising and self._writer is None:
            self.start(reason="go")
        elif not rising and self._writer is not None:
            self.stop()

    def on_sync(self, ev: SyncEvent) -> None:
        with self._lock:
            ev.recording = self.current
            self.sync_events.append(ev)
            if len(self.sync_events) > 100_000:
                del self.sync_events[:10_000]
            if self._sync_file is not None:
                self._sync_file.write(json.dumps(ev.as_dict()) + "\n")
                self._sync_file.flush()

    # -- control ---------------------------------------------------------------------------
    def start(self, reason: str = "manual") -> str:
        """Open a new recording (with the pre-roll); returns its id. No-op if one is open."""
        with self._lock:
            if self._writer is not None:
                return self._writer.path.stem
            if reason == "manual":
                self._manual = True
            stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
            path = self.dir / f"{stamp}.rdrlog"
            k = 1
            while path.exists():
                path = self.dir / f"{stamp}-{k}.rdrlog"
                k += 1
            self._writer = RecordingWriter(path, self.spec, site=self.site, source=self.source,
                                           extra={"started_by": reason})
            for t, d in self._pre:
                self._writer.write(d, t)
            self._pre.clear()
            self._sync_file = open(path.with_suffix(".sync.jsonl"), "a", encoding="utf-8")
            return path.stem

    def stop(self) -> str | None:
        with self._lock:
            self._manual = False
            w, self._writer = self._writer, None
            if self._sync_file is not None:
                self._sync_file.close()
                self._sync_file = None
            if w is None:
                return None
            w.close()
            return w.path.stem

    @property
    def current(self) -> str | None:
        w = self._writer
        return w.path.stem if w is not None else None

    def close(self) -> None:
        self.stop()
