"""Automatic and manual raw recording, the events of each recording, and the clock watch.

The reader thread hands every received chunk to :meth:`Recorder.on_chunk` *before*
decoding. ``on_chunk`` never touches the disk and never waits on a lock held across I/O:
it keeps the chunk in a short pre-roll ring and appends it to a queue, under a lock that
guards memory only. One writer thread (``rdrlog-writer``) owns the files: it creates a
recording (header), writes the queued chunks, the recording's events and sync index, and
hands it over to be closed; every fsync — the header's, the one every second, the final
one before the close — runs on the file's own fsync thread (``rdrlog-fsync``); only an
event that arrives after its recording closed (a sync edge on the GO-fall frame) is
appended and fsynced by the writer itself.

A recording starts at the point of the stream where it was asked for, pre-roll included,
however late its file opens: a recording started by a GO 0→1 edge (seen only after the
chunk that holds it is decoded) begins with that chunk and the pre-roll.

Storage faults never reach the live stream. A write, open or event that fails stays at the
head of the queue and is tried again every ``retry_s``; meanwhile chunks wait in memory up
to ``buffer_bytes`` and are written when the disk takes data again, so a short outage
loses nothing. Chunks beyond the buffer are dropped and counted (``buffer`` on the
status). A manual start whose file cannot be created is refused (StorageError, HTTP 507);
an automatic one, and any recording that fails once open, is retried. ``last_error``
(``recording_error`` on the status) says why the disk is not keeping up; :meth:`storage`
reports the free space with a low-space warning below ``low_space_bytes``.

Events of a recording go to ``<id>.events.jsonl`` beside it, one JSON object per line:
``{"kind", "t_ns", "mono_ns", ...}`` with kinds ``go`` (``edge``: rise / fall), ``sync``
(SEQ, TOD; also indexed in ``<id>.sync.jsonl`` as before), ``clock_step`` (``step_s``),
``alarm`` (from the alarm engine) and ``annotation`` (:meth:`Recorder.annotate`: notes,
markers, test points; ``annotation_kind, label, text, id, actor``). A wall-clock step (the
wall clock moved more than ``CLOCK_STEP_S`` more or less than the monotonic clock between two
chunks) is detected in
``on_chunk`` and shown on the status (:meth:`clock_status`).
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
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any

from radar_io.coordinates.transforms import Site
from radar_io.errors import RadarIOError, RecordingError, StorageError
from radar_io.recording.rdrlog import MAX_CHUNK, RecordingWriter, clock_step_s
from radar_io.wirespec.frame import FrameSpec

AUTO_MODES = ("go", "manual", "always")
#: errno values that mean "no room": HTTP 507 (other disk errors: 503)
NO_SPACE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})  # EFBIG: size limit
LOW_SPACE_BYTES = 1 << 30  #: default low-space warning threshold (1 GiB)
BUFFER_BYTES = 64 << 20    #: default memory for chunks the disk has not taken yet
CLOCK_STEP_S = 0.5         #: a wall-clock jump larger than this between two chunks is a step
WRITE_BATCH_BYTES = 1 << 20  #: chunks handed to the kernel in one write, at most
WRITER_POLL_S = 0.01       #: the writer picks queued chunks up at least this often

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


@dataclass(eq=False)
class _Rec:
    """One recording as asked for (its file may open later)."""

    id: str
    reason: str
    settled: threading.Event = field(default_factory=threading.Event)  #: opened or refused
    closed: threading.Event = field(default_factory=threading.Event)
    error: RadarIOError | None = None  #: why a manual start was refused
    start_t_ns: int = 0  #: wall-clock receive time of its first chunk (pre-roll included)


@dataclass(eq=False, slots=True)
class _Op:
    """One job for the writer: ``chunk``, ``open``, ``close`` or ``event`` (of ``rec``)."""

    kind: str
    rec: _Rec
    data: bytes = b""
    t_ns: int = 0
    mono_ns: int = 0
    event: dict[str, Any] | None = None
    suffix: str = ""


class Recorder:
    """Opens a new ``.rdrlog`` per GO period (``auto="go"``), on request, or continuously.

    The pre-roll ring always holds the last ``preroll_s`` of chunks (monotonic receive
    time; never less than the chunk being decoded plus one frame), so a recording opened
    by an edge found in that chunk starts before the frame that holds the edge, even when
    GO fell and rose again within one read. See the module docstring for the threads.
    """

    def __init__(self, data_dir: Path, spec: FrameSpec, site: Site | None, source: str,
                 auto: str = "go", preroll_s: float = 2.0, retry_s: float = 5.0,
                 low_space_bytes: int = LOW_SPACE_BYTES, buffer_bytes: int = BUFFER_BYTES,
                 fsync_interval_s: float = 1.0) -> None:
        if auto not in AUTO_MODES:
            raise ValueError(f"auto recording mode must be one of {AUTO_MODES}")
        self.dir = data_dir / "recordings"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.spec, self.site, self.source, self.auto = spec, site, source, auto
        self.preroll_s = preroll_s
        self.retry_s = retry_s
        self.low_space_bytes = low_space_bytes
        self.buffer_bytes = buffer_bytes
        self.fsync_interval_s = fsync_interval_s
        self._pre: deque[tuple[int, int, bytes]] = deque()  # (t_ns, mono_ns, data)
        self._pre_bytes = 0
        # memory only: never held across I/O (the reader thread takes it for every chunk)
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._q: deque[_Op] = deque()
        self._q_bytes = 0
        self._rec: _Rec | None = None  # the recording chunks go to now
        self._ids = {p.stem for p in self.dir.glob("*.rdrlog")}  # ids never to reuse
        self._manual = False
        self._want: str | None = None  # automatic recording wanted ("go" / "always")
        if auto == "always":
            self._want = "always"  # opened by the first chunk: no file before data flows
        self.enabled = True  # False: chunks and GO edges are ignored (nothing is recorded)
        #: called with the path of each recording that closed cleanly (e.g. the archiver)
        self.on_closed: Callable[[Path], None] | None = None
        self.sync_events: list[SyncEvent] = []
        #: (id, first t_ns, last t_ns) of the recordings closed since the start, newest last
        self._spans: deque[tuple[str, int, int]] = deque(maxlen=1000)
        self.last_error: str | None = None     #: why the disk is not keeping up (None: it is)
        self.storage_error: str | None = None  #: the last disk error (kept after recovery)
        self.storage_errors = 0
        self.overflow_chunks = 0  #: chunks dropped because the buffer was full
        self.overflow_bytes = 0
        # clock watch (reader thread)
        self._last_t: int | None = None
        self._last_mono: int | None = None
        self.clock_steps = 0
        self.last_clock_step: dict[str, Any] | None = None
        # writer thread state
        self._w: RecordingWriter | None = None
        self._w_rec: _Rec | None = None
        self._closing_files: list[RecordingWriter] = []  # final fsync on their own threads
        self._failing = False
        self._fsync_bad: int | None = None  # fsyncs count when the last fsync failed
        self._closing = False
        self._give_up_mono = float("inf")
        self._writer = threading.Thread(target=self._run, name="rdrlog-writer", daemon=True)
        self._writer.start()

    # -- called by the reader thread: memory only -----------------------------------------
    def on_chunk(self, data: bytes, t_ns: int, mono_ns: int | None = None) -> None:
        """Keep the chunk in the pre-roll and queue it for the open recording.

        ``t_ns``: wall-clock receive time (a label); ``mono_ns``: monotonic receive time
        (default ``t_ns``), on which the pre-roll is measured, so a wall-clock step can
        neither grow nor shrink it. Never raises, never waits on the disk.
        """
        mono = t_ns if mono_ns is None else mono_ns
        with self._lock:
            self._watch_clock(t_ns, mono)
            if not self.enabled:
                return
            self._pre.append((t_ns, mono, data))
            self._pre_bytes += len(data)
            keep = len(data) + self.spec.length  # the frame in progress may start earlier
            while (len(self._pre) > 1 and mono - self._pre[0][1] > self.preroll_s * 1e9
                   and self._pre_bytes - len(self._pre[0][2]) >= keep):
                self._pre_bytes -= len(self._pre.popleft()[2])
            if self._rec is not None:
                self._put_chunk(self._rec, data, t_ns, mono)
            elif self._want is not None:
                self._begin(self._want)  # "always": the first chunk (in the pre-roll) opens it

    def _watch_clock(self, t_ns: int, mono: int) -> None:
        """Note a wall-clock step between the previous chunk and this one (lock held)."""
        if self._last_t is not None and self._last_mono is not None:
            step = clock_step_s(self._last_t, self._last_mono, t_ns, mono)
            if abs(step) > CLOCK_STEP_S:
                self.clock_steps += 1
                self.last_clock_step = {"step_s": round(step, 6), "t_ns": t_ns,
                                        "mono_ns": mono, "count": self.clock_steps}
                if self._rec is not None:
                    self._put_event(self._rec, "clock_step", {"step_s": round(step, 6)},
                                    t_ns, mono)
        self._last_t, self._last_mono = t_ns, mono

    def on_go_edge(self, rising: bool) -> None:
        """GO changed in the chunk just given to :meth:`on_chunk` (a ``go`` event in the
        open recording); in ``go`` mode a rise starts a recording and a fall ends it."""
        with self._lock:
            edge = "rise" if rising else "fall"
            policy = self.auto == "go" and not self._manual and self.enabled
            if rising and policy:
                self._want = "go"
                if self._rec is None:
                    self._begin("go")
            if self._rec is not None:
                self._put_event(self._rec, "go", {"edge": edge})
            if not rising and policy:
                self._want = None
                if self._rec is not None:
                    self._end()
                elif not self._failing:
                    self.last_error = None  # nothing is wanted any more

    def on_sync(self, ev: SyncEvent) -> None:
        """Index a sync event (``ev.recording``: the recording that holds its frame): kept in
        memory, and written by the writer to that recording's events and sync index."""
        with self._lock:
            self.sync_events.append(ev)
            if len(self.sync_events) > 100_000:
                del self.sync_events[:10_000]
            if ev.recording is None:
                return
            rec = self._rec if self._rec is not None and self._rec.id == ev.recording \
                else _Rec(ev.recording, "")  # its file has closed: appended on its own
            self._put_event(rec, "sync", {"seq": ev.seq, "tod_s": ev.tod_s,
                                          "msg_seq": ev.msg_seq}, ev.t_ns)
            self._put(_Op("event", rec, event=ev.as_dict(), suffix=".sync.jsonl"))

    def event(self, kind: str, fields: dict[str, Any], t_ns: int | None = None,
              mono_ns: int | None = None) -> str | None:
        """Add an event (``kind``, e.g. ``alarm``) to the open recording; any thread, never
        waits. Returns the recording's id, or None when none is open (nothing written)."""
        with self._lock:
            if self._rec is None:
                return None
            self._put_event(self._rec, kind, fields, t_ns, mono_ns)
            return self._rec.id

    def annotate(self, fields: dict[str, Any], t_ns: int) -> str | None:
        """Add an ``annotation`` event at wall-clock ``t_ns`` to the recording open at that
        time — the open one, or one closed since the service started — through the writer
        (any thread, never waits). Returns its id, or None when no recording held ``t_ns``."""
        mono = time.monotonic_ns() - (time.time_ns() - t_ns)  # the same instant, monotonic
        with self._lock:
            rec = self._rec if self._rec is not None and t_ns >= self._rec.start_t_ns else None
            if rec is None:
                for rid, t0, t1 in reversed(self._spans):
                    if t0 <= t_ns <= t1:
                        rec = _Rec(rid, "")  # its file has closed: appended on its own
                        break
            if rec is None:
                return None
            self._put_event(rec, "annotation", fields, t_ns, mono)
            return rec.id

    # -- queue (lock held) ----------------------------------------------------------------
    def _put(self, op: _Op) -> None:
        self._q.append(op)
        if op.kind != "chunk":
            self._cond.notify()

    def _put_chunk(self, rec: _Rec, data: bytes, t_ns: int, mono: int) -> None:
        if self._q_bytes + len(data) > self.buffer_bytes:  # logged by the writer
            self.overflow_chunks += 1
            self.overflow_bytes += len(data)
            return
        for k in range(0, max(len(data), 1), MAX_CHUNK):
            self._q.append(_Op("chunk", rec, data[k:k + MAX_CHUNK], t_ns, mono))
        self._q_bytes += len(data)

    def _put_event(self, rec: _Rec, kind: str, fields: dict[str, Any], t_ns: int | None = None,
                   mono_ns: int | None = None) -> None:
        t = self._last_t if t_ns is None else t_ns
        m = self._last_mono if mono_ns is None else mono_ns
        ev = {"kind": kind, "t_ns": time.time_ns() if t is None else t,  # a label
              "mono_ns": time.monotonic_ns() if m is None else m, **fields}
        self._put(_Op("event", rec, event=ev, suffix=".events.jsonl"))

    def _begin(self, reason: str) -> _Rec:
        """A new recording from this point of the stream, pre-roll included."""
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())  # a label (wall clock)
        rid, k = stamp, 1
        while rid in self._ids:
            rid, k = f"{stamp}-{k}", k + 1
        self._ids.add(rid)
        start = self._pre[0][0] if self._pre else (self._last_t or time.time_ns())
        rec = self._rec = _Rec(rid, reason, start_t_ns=start)
        self._put(_Op("open", rec))
        for t, mono, d in self._pre:
            self._put_chunk(rec, d, t, mono)
        return rec

    def _end(self) -> _Rec | None:
        rec, self._rec = self._rec, None
        self._manual = False
        if rec is not None:
            self._spans.append((rec.id, rec.start_t_ns, self._last_t or time.time_ns()))
            self._put(_Op("close", rec))
        return rec

    # -- control (any thread but the reader's) ----------------------------------------------
    def start(self, reason: str = "manual", wait_s: float = 5.0) -> str:
        """Start a recording (with the pre-roll) unless one is open; returns its id.

        Waits up to ``wait_s`` for its file to open: a manual start whose file cannot be
        created raises StorageError (no space → errno ENOSPC, read-only, I/O error) after
        setting ``last_error``; no file and no fd are left behind.
        """
        with self._lock:
            new = self._rec is None
            rec = self._begin(reason) if self._rec is None else self._rec
            if reason == "manual":
                self._manual = True  # a GO fall no longer ends it
        if new and wait_s > 0:
            rec.settled.wait(wait_s)
            if rec.error is not None:
                raise rec.error
        return rec.id

    def stop(self, wait_s: float = 5.0) -> str | None:
        """End the open recording (its id, or None); waits up to ``wait_s`` for its file to
        be closed (a final fsync failure is reported in ``last_error``)."""
        with self._lock:
            self._want = None  # an operator's stop (or GO falling) wins: no automatic restart
            rec = self._end()
        if rec is None:
            return None
        if wait_s > 0:
            rec.closed.wait(wait_s)
        return rec.id

    def committed_bytes(self, rec_id: str) -> int | None:
        """Bytes of recording ``rec_id`` up to its last whole chunk while the writer holds
        its file open (None otherwise: the file is complete): a consistent snapshot."""
        w = self._w
        if w is None or w.path.stem != rec_id:
            return None
        return w.committed_bytes

    @staticmethod
    def http_status(exc: StorageError) -> int:
        """507 when the disk has no room (ENOSPC, EDQUOT, EFBIG), else 503."""
        return 507 if exc.errno in NO_SPACE_ERRNOS else 503

    def storage(self) -> dict[str, Any]:
        """Free space of the recordings directory, the last disk error and the buffer."""
        try:
            free: int | None = shutil.disk_usage(self.dir).free
        except OSError:
            free = None
        return {"free_bytes": free, "low_space": free is not None and free < self.low_space_bytes,
                "low_space_bytes": self.low_space_bytes, "last_error": self.storage_error,
                "errors": self.storage_errors, "buffer": self.buffer_status()}

    def buffer_status(self) -> dict[str, int]:
        """Chunks waiting for the disk (``pending_bytes``, ``limit_bytes``) and dropped."""
        return {"pending_bytes": self._q_bytes, "limit_bytes": self.buffer_bytes,
                "overflow_chunks": self.overflow_chunks, "overflow_bytes": self.overflow_bytes}

    def clock_status(self) -> dict[str, Any]:
        """Wall-clock steps seen between chunks: ``steps`` and the ``last_step`` (``step_s``,
        ``t_ns``, ``mono_ns``, ``count``), or None."""
        return {"steps": self.clock_steps, "last_step": self.last_clock_step,
                "step_threshold_s": CLOCK_STEP_S}

    @property
    def current(self) -> str | None:
        """The recording chunks go to now (its file may still be opening)."""
        rec = self._rec
        return rec.id if rec is not None else None

    def close(self, timeout_s: float = 5.0) -> None:
        """End the open recording and let the writer finish the queue (given up after
        ``timeout_s`` if the disk does not take it)."""
        self.stop(wait_s=0)
        with self._lock:
            self._closing = True
            self._give_up_mono = time.monotonic() + timeout_s
            self._cond.notify()
        self._writer.join(timeout_s + 1.0)
        for w in self._closing_files:  # final fsyncs
            w.join(max(0.0, self._give_up_mono + 1.0 - time.monotonic()))

    # -- the writer thread ------------------------------------------------------------------
    def _run(self) -> None:
        logged_overflow = 0
        while True:
            if self.overflow_chunks != logged_overflow:  # said here: the reader never logs
                logged_overflow = self.overflow_chunks
                log.error("recording buffer full (%d bytes): %d chunks dropped so far",
                          self.buffer_bytes, logged_overflow)
            with self._lock:
                while not self._q and not self._closing:
                    self._cond.wait(WRITER_POLL_S if self._w is not None else None)
                if not self._q:
                    break
                ops = self._head()
            try:
                self._do(ops)
            except (OSError, RadarIOError) as exc:
                if self._refuse(ops[0], exc):
                    continue
                self._note(exc)
                self._failing = True
                if not self._backoff():
                    self._abandon()
                    return
                continue
            except Exception:  # a bug: drop this job, keep the writer alive
                log.exception("recording: %s job failed, dropped", ops[0].kind)
            self._done(ops)
        if self._w is not None:
            self._close_file()

    def _head(self) -> list[_Op]:
        """The next job: one control op or a run of chunks of one recording (lock held)."""
        first = self._q[0]
        if first.kind != "chunk":
            return [first]
        ops, size = [], 0
        for op in islice(self._q, 0, 4096):
            if op.kind != "chunk" or op.rec is not first.rec or size >= WRITE_BATCH_BYTES:
                break
            ops.append(op)
            size += len(op.data)
        return ops

    def _done(self, ops: list[_Op]) -> None:
        with self._lock:
            for _ in ops:
                op = self._q.popleft()
                if op.kind == "chunk":
                    self._q_bytes -= len(op.data)
        if self._failing:
            self._failing = False
            self.last_error = None
            log.info("recording: the disk takes data again")
        w = self._w
        if w is not None:
            err = w.take_fsync_error()
            if err is not None:
                self._note(err)
                self._fsync_bad = w.fsyncs
            elif self._fsync_bad is not None and w.fsyncs > self._fsync_bad:
                self._fsync_bad = None
                if not self._failing:
                    self.last_error = None

    def _do(self, ops: list[_Op]) -> None:
        op = ops[0]
        if op.kind == "chunk":
            if self._w is not None and self._w_rec is op.rec:
                self._w.write_chunks([(o.data, o.t_ns, o.mono_ns) for o in ops])
        elif op.kind == "open":
            self._open_file(op.rec)
        elif op.kind == "close":
            if self._w_rec is op.rec:
                self._close_file()  # rec.closed is set once the file is closed
            else:
                op.rec.closed.set()
        elif op.kind == "event" and op.event is not None:
            try:
                line = (json.dumps(op.event, allow_nan=False, default=str) + "\n").encode()
            except ValueError:  # a non-finite number somewhere: the event is dropped, said once
                log.error("event %r of %s not written: not valid JSON", op.event.get("kind"),
                          op.rec.id)
                return
            if self._w is not None and self._w_rec is not None and self._w_rec.id == op.rec.id:
                self._w.write_sidecar(op.suffix, line)
            else:  # a recording already closed (e.g. the sync edge on the GO-fall frame)
                self._append(self.dir / f"{op.rec.id}{op.suffix}", line)

    def _open_file(self, rec: _Rec) -> None:
        if self._w is not None:  # cannot happen (closes come first); keep files whole
            self._close_file()
        while True:
            path = self.dir / f"{rec.id}.rdrlog"
            try:
                w = RecordingWriter(path, self.spec, site=self.site, source=self.source,
                                    fsync_interval_s=self.fsync_interval_s,
                                    extra={"started_by": rec.reason}, sync_header=False)
                break
            except RecordingError:
                if not path.exists():
                    raise
                rec.id += "-1"  # a file of that name appeared since: never overwritten
        self._w, self._w_rec = w, rec
        rec.settled.set()
        log.info("recording %s started (%s)", path.name, rec.reason)

    def _close_file(self) -> None:
        """Hand the file to its fsync thread for the final fsync and close: the writer
        goes on with the next recording at once (the file is complete already)."""
        w, rec = self._w, self._w_rec
        self._w = self._w_rec = None
        if w is None:
            return
        self._fsync_bad = None
        self._closing_files = [c for c in self._closing_files if not c.closed] + [w]

        def then(err: StorageError | None) -> None:  # on the file's fsync thread
            if err is not None:
                self._note(err)
            else:
                log.info("recording %s closed (%d chunks, %d bytes)", w.path.name, w.chunks,
                         w.bytes)
                if self.on_closed is not None:
                    try:
                        self.on_closed(w.path)
                    except Exception:  # closing must finish
                        log.exception("on_closed(%s) failed", w.path)
            if rec is not None:
                rec.closed.set()

        w.close_later(then)

    @staticmethod
    def _append(path: Path, line: bytes) -> None:
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        except OSError as exc:
            raise StorageError(f"cannot write {path}: {exc.strerror}", errno=exc.errno) from exc
        try:
            os.write(fd, line)
            os.fsync(fd)
        except OSError as exc:
            raise StorageError(f"cannot write {path}: {exc.strerror}", errno=exc.errno) from exc
        finally:
            os.close(fd)

    def _refuse(self, op: _Op, exc: Exception) -> bool:
        """A manual start whose file cannot be created is refused, not retried: its ops
        leave the queue and the caller of :meth:`start` gets the error. True if so."""
        if op.kind != "open" or op.rec.reason != "manual" or not isinstance(exc, RadarIOError):
            return False
        self._note(exc)
        self._failing = True  # shown until the disk takes something again
        rec = op.rec
        with self._lock:
            kept = deque(o for o in self._q if o.rec is not rec)
            self._q_bytes -= sum(len(o.data) for o in self._q if o.rec is rec)
            self._q = kept
            if self._rec is rec:
                self._rec = None
                self._manual = False
        rec.error = exc
        rec.settled.set()
        rec.closed.set()
        return True

    def _backoff(self) -> bool:
        """Wait ``retry_s`` before trying the head of the queue again; False when closing
        and the time to finish is up."""
        with self._lock:
            deadline = time.monotonic() + self.retry_s
            while True:
                now = time.monotonic()
                if self._closing and now >= self._give_up_mono:
                    return False
                if now >= deadline:
                    return True
                self._cond.wait(min(deadline, self._give_up_mono) - now)

    def _abandon(self) -> None:
        """Shutting down with the disk still failing: what is queued is lost (logged)."""
        with self._lock:
            lost = sum(1 for o in self._q if o.kind == "chunk")
            self._q.clear()
            self._q_bytes = 0
        log.error("recording: the disk did not recover before shutdown; %d chunks lost", lost)
        if self._w is not None:
            self._close_file()

    def _note(self, exc: Exception) -> None:
        msg = str(exc)
        if msg != self.last_error:
            log.error("recording: %s", msg)
        self.last_error = msg
        if isinstance(exc, StorageError):
            self.storage_error = msg
            self.storage_errors += 1
