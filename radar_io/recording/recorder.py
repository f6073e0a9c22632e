"""Automatic and manual raw recording, and the index of sync (camera shutter) events.

The reader thread hands every received chunk to :meth:`Recorder.on_chunk`
*before* decoding. While no recording is open the recent chunks sit in a short
pre-roll ring, so a recording started by a GO 0→1 edge (seen only after the
chunk that holds it is decoded) still begins with that chunk and the pre-roll.

Storage faults never reach the live stream: a recording that cannot be opened or
written sets ``last_error`` (``recording_error`` on the status) and is logged; the
automatic modes (``always``, and ``go`` while GO is high) try again every ``retry_s``
and record from the moment the disk takes data again. :meth:`storage` reports the free
space with a low-space warning below ``low_space_bytes``.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import shutil
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from radar_io.coordinates.transforms import Site
from radar_io.errors import RadarIOError, StorageError
from radar_io.recording.rdrlog import RecordingWriter
from radar_io.wirespec.frame import FrameSpec

AUTO_MODES = ("go", "manual", "always")
#: errno values that mean "no room": HTTP 507 (other disk errors: 503)
NO_SPACE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})  # EFBIG: size limit
LOW_SPACE_BYTES = 1 << 30  #: default low-space warning threshold (1 GiB)

log = logging.getLogger("radar_io.recording")


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
                 auto: str = "go", preroll_s: float = 2.0, retry_s: float = 5.0,
                 low_space_bytes: int = LOW_SPACE_BYTES) -> None:
        if auto not in AUTO_MODES:
            raise ValueError(f"auto recording mode must be one of {AUTO_MODES}")
        self.dir = data_dir / "recordings"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.spec, self.site, self.source, self.auto = spec, site, source, auto
        self.preroll_s = preroll_s
        self.retry_s = retry_s
        self.low_space_bytes = low_space_bytes
        self._pre: deque[tuple[int, int, bytes]] = deque()  # (t_ns, mono_ns, data)
        self._pre_bytes = 0
        self._writer: RecordingWriter | None = None
        self._lock = threading.Lock()
        self._manual = False
        self.enabled = True  # False: chunks and GO edges are ignored (nothing is recorded)
        #: called with the path of each recording that closed cleanly (e.g. the archiver)
        self.on_closed: Callable[[Path], None] | None = None
        self.sync_events: list[SyncEvent] = []
        self.last_error: str | None = None        #: why the wanted recording is not running
        self.storage_error: str | None = None     #: the last disk error (kept after recovery)
        self.storage_errors = 0
        self._want: str | None = None             #: automatic recording wanted ("go"/"always")
        self._next_try = 0.0                      #: monotonic time of the next automatic retry
        self._retry = False                       #: an automatic recording failed: retry it
        if auto == "always":
            self._want = "always"
            self._retry = True  # opened by the first chunk: no file before data flows

    # -- called by the reader thread ---------------------------------------------------------
    def on_chunk(self, data: bytes, t_ns: int, mono_ns: int | None = None) -> None:
        """Keep the chunk in the pre-roll and append it to the open recording.

        ``t_ns``: wall-clock receive time (a label); ``mono_ns``: monotonic receive time
        (default ``t_ns``), on which the pre-roll is measured, so a wall-clock step can
        neither grow nor shrink it.

        Never raises: a failing disk closes the recording (``last_error``, logged) and the
        caller carries on decoding; an automatic mode retries every ``retry_s``.
        """
        with self._lock:
            if not self.enabled:
                return
            mono = t_ns if mono_ns is None else mono_ns
            self._pre.append((t_ns, mono, data))
            self._pre_bytes += len(data)
            keep = len(data) + self.spec.length  # the frame in progress may start earlier
            while (len(self._pre) > 1 and mono - self._pre[0][1] > self.preroll_s * 1e9
                   and self._pre_bytes - len(self._pre[0][2]) >= keep):
                self._pre_bytes -= len(self._pre.popleft()[2])
            if self._writer is not None:
                try:
                    self._writer.write(data, t_ns, mono)
                except RadarIOError as exc:
                    self._fail(exc)
                return
            if not self._retry or self._want is None or time.monotonic() < self._next_try:
                return
        self._try_auto()

    def _fail(self, exc: Exception) -> None:
        """The open recording failed: close it, report, schedule a retry (lock held)."""
        self._note(exc)
        w, self._writer = self._writer, None
        if w is not None:
            try:
                w.close()
            except (OSError, RadarIOError):
                pass
        if self._want is None and self._manual:
            self._manual = False

    def _note(self, exc: Exception) -> None:
        self.last_error = str(exc)
        if isinstance(exc, StorageError):
            self.storage_error = str(exc)
            self.storage_errors += 1
        self._next_try = time.monotonic() + self.retry_s
        self._retry = self._want is not None
        log.error("recording: %s", exc)

    def _try_auto(self) -> None:
        """Open the automatically wanted recording; failures are reported, never raised."""
        want = self._want
        if want is None or not self.enabled:
            return
        try:
            self.start(reason=want)
        except RadarIOError:
            pass  # reported by start(); retried after retry_s

    def on_go_edge(self, rising: bool) -> None:
        if self.auto != "go" or self._manual or not self.enabled:
            return
        if rising:
            self._want = "go"
            if self._writer is None:
                self._try_auto()
        else:
            self._want = None
            if self._writer is not None:
                self.stop()
            else:
                self.last_error = None  # nothing is wanted any more

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
        """Open a new recording (with the pre-roll); returns its id. No-op if one is open.

        Raises StorageError (no space → errno ENOSPC, read-only, I/O error) after setting
        ``last_error``; no file and no fd are left behind.
        """
        with self._lock:
            if self._writer is None:
                stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
                path = self.dir / f"{stamp}.rdrlog"
                k = 1
                while path.exists():
                    path = self.dir / f"{stamp}-{k}.rdrlog"
                    k += 1
                try:
                    writer = RecordingWriter(path, self.spec, site=self.site, source=self.source,
                                             extra={"started_by": reason})
                except RadarIOError as exc:
                    self._note(exc)
                    raise
                try:
                    for t, mono, d in self._pre:
                        writer.write(d, t, mono)
                except RadarIOError as exc:  # no room for the pre-roll: do not keep a stub
                    try:
                        writer.close()
                    except RadarIOError:
                        pass
                    try:
                        os.unlink(path)
                    except OSError:
                        pass
                    self._note(exc)
                    raise
                self._writer = writer
                self.last_error = None
                self._retry = False
                log.info("recording %s started (%s)", path.name, reason)
            if reason == "manual":
                self._manual = True  # a GO fall no longer ends it
            return self._writer.path.stem

    def stop(self) -> str | None:
        """Close the open recording (its id, or None). A final fsync failure is reported
        in ``last_error`` (the file stays, as complete as the disk allowed)."""
        with self._lock:
            self._manual = False
            self._want = None  # an operator's stop (or GO falling) wins: no automatic restart
            self._retry = False
            w, self._writer = self._writer, None
            if w is None:
                return None
            try:
                w.close()
            except RadarIOError as exc:
                self._note(exc)
                return w.path.stem
        if self.on_closed is not None:
            self.on_closed(w.path)
        return w.path.stem

    def committed_bytes(self, rec_id: str) -> int | None:
        """Bytes of the open recording ``rec_id`` up to its last whole chunk (None when
        ``rec_id`` is not the open recording): the size of a consistent snapshot."""
        w = self._writer
        if w is None or w.path.stem != rec_id:
            return None
        return w.committed_bytes

    @staticmethod
    def http_status(exc: StorageError) -> int:
        """507 when the disk has no room (ENOSPC, EDQUOT, EFBIG), else 503."""
        return 507 if exc.errno in NO_SPACE_ERRNOS else 503

    def storage(self) -> dict[str, Any]:
        """Free space of the recordings directory and the last disk error."""
        try:
            free: int | None = shutil.disk_usage(self.dir).free
        except OSError:
            free = None
        return {"free_bytes": free, "low_space": free is not None and free < self.low_space_bytes,
                "low_space_bytes": self.low_space_bytes, "last_error": self.storage_error,
                "errors": self.storage_errors}

    @property
    def current(self) -> str | None:
        w = self._writer
        return w.path.stem if w is not None else None

    def close(self) -> None:
        self.stop()
