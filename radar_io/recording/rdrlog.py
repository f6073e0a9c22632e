"""``.rdrlog`` recordings: the raw received bytes, append-only and crash-safe.

File layout, format version 2 (all integers big-endian)::

    file header   magic   8 bytes  b"RDRLOG\\x00\\x02"
                  hlen    u32      length of the JSON header
                  header  hlen     UTF-8 JSON: format ("rdrlog/2"), spec_version, spec_sha256,
                                   site, source, created_utc, software, clock
                  hcrc    u32      zlib.crc32 of the JSON header
    chunk …       magic   4 bytes  b"CHK2"
                  t_ns    u64      receive time, ns since the Unix epoch (UTC): a label
                  mono_ns u64      receive time on the monotonic clock (CLOCK_MONOTONIC, ns):
                                   what every duration, pacing and seek is measured on
                  length  u32      payload length (at most 16 MiB)
                  crc     u32      zlib.crc32 of t_ns|mono_ns|length|payload (20 + length bytes)
                  payload length   the bytes exactly as received

Version 1 (magic ``RDRLOG\\x00\\x01``, format ``rdrlog/1``) has chunks ``CHK1 | t_ns |
length | crc`` (crc over ``t_ns|length|payload``) and no monotonic time; the reader keeps
reading it and gives its chunks ``mono_ns = t_ns``. The writer writes version 2 only.

The two clocks: a wall-clock step (NTP, an operator setting the date) moves ``t_ns`` but not
``mono_ns``; the difference of their deltas between two chunks is the step
(:func:`clock_step_s`).

Each chunk is handed to the kernel in one ``write`` on an ``O_APPEND`` file, so
a ``kill -9`` of the writer loses nothing it had written; ``fsync`` runs every
``fsync_interval_s`` on a background thread, for power loss. Disk trouble is a
:class:`~radar_io.errors.StorageError` carrying the OS ``errno`` (ENOSPC → HTTP 507):
a file that cannot get its header is closed and removed (no fd, no empty file left);
a failed ``fsync`` is kept in ``fsync_error`` and raised by the next ``write``/``close``
(or taken by :meth:`RecordingWriter.take_fsync_error`, which lets writing go on). Files
beside the recording (``.events.jsonl``, ``.sync.jsonl``: :meth:`RecordingWriter.write_sidecar`)
are fsynced with it.
``committed_bytes`` is the file size up to the last whole chunk: a download of an open
recording sends exactly that many bytes. A reader returns every complete chunk; a
torn tail (a chunk cut short by a crash) is reported and skipped, and a damaged
chunk in the middle is counted and skipped by hunting for the next valid chunk.
"""

from __future__ import annotations

import errno as _errno
import json
import logging
import os
import struct
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from radar_io import __version__
from radar_io.coordinates.transforms import Site
from radar_io.errors import RecordingError, StorageError
from radar_io.textfiles import open_input
from radar_io.wirespec.frame import FrameSpec

FILE_MAGIC = b"RDRLOG\x00\x02"
CHUNK_MAGIC = b"CHK2"
_CHUNK_HEAD = struct.Struct(">4sQQII")  # magic, t_ns, mono_ns, length, crc
FORMAT = "rdrlog/2"
#: version 1 (read only): no monotonic time
FILE_MAGIC_V1 = b"RDRLOG\x00\x01"
CHUNK_MAGIC_V1 = b"CHK1"
_CHUNK_HEAD_V1 = struct.Struct(">4sQII")  # magic, t_ns, length, crc
FORMAT_V1 = "rdrlog/1"
MAX_CHUNK = 16 << 20

log = logging.getLogger("radar_io.recording")


def storage_error(what: str, path: str | os.PathLike[str], exc: OSError) -> StorageError:
    """A StorageError naming the file and the OS reason, with its errno."""
    reason = exc.strerror or str(exc)
    if exc.errno == _errno.EFBIG:
        reason = "file too large (size limit reached)"
    return StorageError(f"{what} {path}: {reason}", errno=exc.errno)


def is_recording(path: str | os.PathLike[str]) -> bool:
    """True if the file starts with an ``.rdrlog`` magic (either version)."""
    try:
        with open(path, "rb") as f:
            return f.read(len(FILE_MAGIC)) in (FILE_MAGIC, FILE_MAGIC_V1)
    except OSError:
        return False


def _chunk_crc(t_ns: int, mono_ns: int, payload: bytes | memoryview) -> int:
    return zlib.crc32(payload, zlib.crc32(struct.pack(">QQI", t_ns, mono_ns, len(payload))))


def _chunk_crc_v1(t_ns: int, payload: bytes | memoryview) -> int:
    return zlib.crc32(payload, zlib.crc32(struct.pack(">QI", t_ns, len(payload))))


def encode_chunk(payload: bytes, t_ns: int, mono_ns: int | None = None) -> bytes:
    """The bytes of one version-2 chunk (header + payload); ``mono_ns`` defaults to ``t_ns``."""
    mono = t_ns if mono_ns is None else mono_ns
    return _CHUNK_HEAD.pack(CHUNK_MAGIC, t_ns, mono, len(payload),
                            _chunk_crc(t_ns, mono, payload)) + payload


def encode_chunk_v1(payload: bytes, t_ns: int) -> bytes:
    """The bytes of one version-1 chunk (for tests and tools that make old files)."""
    return _CHUNK_HEAD_V1.pack(CHUNK_MAGIC_V1, t_ns, len(payload),
                               _chunk_crc_v1(t_ns, payload)) + payload


def clock_step_s(prev_t_ns: int, prev_mono_ns: int, t_ns: int, mono_ns: int) -> float:
    """Wall-clock step between two chunks, s: how much more the wall clock moved than the
    monotonic clock (positive = set forward)."""
    return ((t_ns - prev_t_ns) - (mono_ns - prev_mono_ns)) / 1e9


class RecordingWriter:
    """Append raw received chunks to a new ``.rdrlog`` file."""

    def __init__(self, path: str | os.PathLike[str], spec: FrameSpec, *, site: Site | None = None,
                 source: str = "", fsync_interval_s: float = 1.0,
                 extra: dict[str, Any] | None = None, sync_header: bool = True) -> None:
        """``sync_header=False``: the header's fsync is left to the fsync thread (its first
        job), so the caller does not wait for the disk."""
        self.path = Path(path)
        self.fsync_interval_s = fsync_interval_s
        self.header: dict[str, Any] = {
            "format": FORMAT,
            "spec": spec.name,
            "spec_version": spec.spec_version,
            "spec_sha256": spec.sha256,
            "site": site.to_dict() if site is not None else None,
            "source": source,
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "software": f"radar_io {__version__}",
            "clock": "t_ns: receive time, ns since the Unix epoch (CLOCK_REALTIME), a label; "
                     "mono_ns: receive time on CLOCK_MONOTONIC, for durations",
            **(extra or {}),
        }
        try:
            self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
        except FileExistsError as exc:
            raise RecordingError(f"recording already exists, not overwriting: {self.path}") from exc
        except OSError as exc:
            raise storage_error("cannot create recording", self.path, exc) from exc
        hdr = json.dumps(self.header, sort_keys=True).encode()
        try:
            self._write(FILE_MAGIC + struct.pack(">I", len(hdr)) + hdr + struct.pack(">I", zlib.crc32(hdr)))
            if sync_header:
                os.fsync(self._fd)
        except OSError as exc:  # no room even for the header: leave neither fd nor file behind
            os.close(self._fd)
            self._fd = -1
            try:
                os.unlink(self.path)
            except OSError:
                pass
            raise storage_error("cannot create recording", self.path, exc) from exc
        self.committed_bytes = os.fstat(self._fd).st_size
        self.chunks = 0
        self.bytes = 0
        self.fsync_error: StorageError | None = None
        self.fsyncs = 0  #: fsyncs that succeeded (periodic ones)
        self._sidecars: dict[str, int] = {}  # suffix → fd, fsynced and closed with the file
        # fsync on a thread of its own: a slow disk never holds up the writer (the reader)
        self._closing = threading.Event()
        self._then: Callable[[StorageError | None], None] | None = None
        self._syncer = threading.Thread(target=self._sync_loop, args=(not sync_header,),
                                        name="rdrlog-fsync", daemon=True)
        self._syncer.start()

    def _sync_loop(self, now: bool) -> None:
        if now:
            self._fsync()
        while not self._closing.wait(self.fsync_interval_s):
            self._fsync()
        if self._then is not None:  # close_later(): the final fsync and close are ours
            try:
                self._final()
            except StorageError as exc:
                self._then(exc)
            else:
                self._then(None)

    def _fsync(self) -> None:
        fd = self._fd
        if fd < 0:
            return
        try:
            for side in list(self._sidecars.values()):
                os.fsync(side)
            os.fsync(fd)
            self.fsyncs += 1
        except OSError as exc:  # surfaced: logged now, raised by the next write / close
            if fd == self._fd and self.fsync_error is None:
                self.fsync_error = storage_error("fsync failed for recording", self.path, exc)
                log.error("%s", self.fsync_error)

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            if n == 0:
                raise OSError(_errno.ENOSPC, os.strerror(_errno.ENOSPC))
            view = view[n:]

    def write(self, payload: bytes, t_ns: int | None = None, mono_ns: int | None = None) -> None:
        """Append one chunk of received bytes with its receive time on both clocks
        (default: now; ``mono_ns`` given alone is paired with the wall clock now)."""
        if len(payload) > MAX_CHUNK:
            for k in range(0, len(payload), MAX_CHUNK):
                self.write(payload[k:k + MAX_CHUNK], t_ns, mono_ns)
            return
        if self.fsync_error is not None:
            raise self.fsync_error
        t = time.time_ns() if t_ns is None else t_ns  # a label only
        mono = (time.monotonic_ns() if t_ns is None else t_ns) if mono_ns is None else mono_ns
        self.write_chunks([(bytes(payload), t, mono)])

    def write_chunks(self, chunks: list[tuple[bytes, int, int]]) -> None:
        """Append ``(payload, t_ns, mono_ns)`` chunks in one ``write`` (payloads at most
        ``MAX_CHUNK``). On failure the file is cut back to its last whole chunk (none of
        these is kept) and StorageError raised; ``fsync_error`` is not looked at."""
        if self._fd < 0:
            raise RecordingError(f"recording {self.path} is closed")
        blob = b"".join(encode_chunk(p, t, m) for p, t, m in chunks)
        try:
            self._write(blob)
        except OSError as exc:
            try:  # a chunk written in part: cut it off so the file ends on a whole chunk
                os.ftruncate(self._fd, self.committed_bytes)
            except OSError:
                pass
            raise storage_error("cannot write recording", self.path, exc) from exc
        self.chunks += len(chunks)
        self.bytes += sum(len(p) for p, _, _ in chunks)
        self.committed_bytes += len(blob)

    def take_fsync_error(self) -> StorageError | None:
        """The failed periodic fsync since the last call, if any (cleared: writing goes on
        and the fsync thread keeps trying)."""
        err, self.fsync_error = self.fsync_error, None
        return err

    def write_sidecar(self, suffix: str, data: bytes) -> None:
        """Append ``data`` to the file beside this one with ``suffix`` (``.events.jsonl``),
        opened on first use, fsynced by the fsync thread and closed with the recording."""
        fd = self._sidecars.get(suffix)
        path = self.path.with_suffix(suffix)
        try:
            if fd is None:
                fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
                self._sidecars[suffix] = fd
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
        except OSError as exc:
            raise storage_error("cannot write", path, exc) from exc

    def close(self) -> None:
        """Stop the fsync thread, fsync and close; a failed fsync (now or earlier) raises
        StorageError after the fd is closed."""
        if self._fd >= 0:
            self._closing.set()
            self._syncer.join()
            self._final()

    def close_later(self, then: Callable[[StorageError | None], None]) -> None:
        """Close on the fsync thread (final fsync included): no more writes may follow;
        ``then(error)`` is called there when the file is closed. :meth:`join` waits."""
        self._then = then
        self._closing.set()

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the fsync thread (and a :meth:`close_later`); True when it has ended."""
        self._syncer.join(timeout_s)
        return not self._syncer.is_alive()

    def _final(self) -> None:
        if self._fd >= 0:
            try:
                for side in self._sidecars.values():
                    os.fsync(side)
                os.fsync(self._fd)
            except OSError as exc:
                if self.fsync_error is None:
                    self.fsync_error = storage_error("fsync failed for recording", self.path, exc)
            finally:
                for side in self._sidecars.values():
                    os.close(side)
                self._sidecars.clear()
                os.close(self._fd)
                self._fd = -1
            if self.fsync_error is not None:
                raise self.fsync_error

    @property
    def closed(self) -> bool:
        return self._fd < 0

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class Chunk:
    """One recorded chunk: receive time (ns since the epoch), payload, file offset of its
    header, monotonic receive time (ns; = ``t_ns`` in a version-1 file) and the size of its
    header (the payload starts at ``offset + head_size``)."""

    t_ns: int
    data: bytes
    offset: int
    mono_ns: int = 0
    head_size: int = _CHUNK_HEAD.size


@dataclass
class ReadReport:
    """What a reader met besides good chunks."""

    chunks: int = 0
    bytes: int = 0
    corrupt_chunks: int = 0
    skipped_bytes: int = 0
    torn_tail_bytes: int = 0
    problems: list[str] = field(default_factory=list)


class RecordingReader:
    """Iterate the chunks of a ``.rdrlog`` in constant memory; never fails on a damaged body."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._f: BinaryIO = open_input(self.path, "recording", RecordingError)
        self.size = os.fstat(self._f.fileno()).st_size
        self.version = 2
        self.header = self._read_header()
        self.data_offset = self._f.tell()
        self._head = _CHUNK_HEAD if self.version == 2 else _CHUNK_HEAD_V1
        self._magic = CHUNK_MAGIC if self.version == 2 else CHUNK_MAGIC_V1
        self.report = ReadReport()

    def _read_header(self) -> dict[str, Any]:
        f = self._f
        magic = f.read(len(FILE_MAGIC))
        if magic not in (FILE_MAGIC, FILE_MAGIC_V1):
            raise RecordingError(f"{self.path} is not an .rdrlog recording (bad magic)")
        self.version = 2 if magic == FILE_MAGIC else 1
        raw = f.read(4)
        if len(raw) < 4:
            raise RecordingError(f"{self.path}: header truncated")
        (hlen,) = struct.unpack(">I", raw)
        if hlen > 1 << 20:
            raise RecordingError(f"{self.path}: header length {hlen} is implausible")
        hdr, crc = f.read(hlen), f.read(4)
        if len(hdr) < hlen or len(crc) < 4 or zlib.crc32(hdr) != struct.unpack(">I", crc)[0]:
            raise RecordingError(f"{self.path}: header damaged or truncated")
        try:
            doc = json.loads(hdr)
        except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
            raise RecordingError(f"{self.path}: header is not valid JSON") from exc
        if not isinstance(doc, dict):
            raise RecordingError(f"{self.path}: header is not a JSON object")
        if doc.get("format") != (FORMAT if self.version == 2 else FORMAT_V1):
            raise RecordingError(f"{self.path}: unsupported recording format {doc.get('format')!r}")
        return doc

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> RecordingReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _unpack(self, head: bytes) -> tuple[bytes, int, int, int, int]:
        """magic, t_ns, mono_ns, length, crc of a chunk header of this file's version."""
        if self.version == 2:
            return _CHUNK_HEAD.unpack(head)
        magic, t_ns, length, crc = _CHUNK_HEAD_V1.unpack(head)
        return magic, t_ns, t_ns, length, crc

    def _crc(self, t_ns: int, mono_ns: int, payload: bytes) -> int:
        return _chunk_crc(t_ns, mono_ns, payload) if self.version == 2 \
            else _chunk_crc_v1(t_ns, payload)

    @property
    def chunk_head_size(self) -> int:
        """Bytes of a chunk header in this file (the payload follows it)."""
        return self._head.size

    def __iter__(self) -> Iterator[Chunk]:
        """Good chunks in file order, from the start; see :attr:`report` afterwards."""
        return self.chunks()

    def chunks(self, start: int | None = None, end: int | None = None) -> Iterator[Chunk]:
        """Good chunks in file order from file offset ``start`` (a chunk boundary; default:
        the first chunk) up to offset ``end`` (default: the file size; e.g. the
        ``committed_bytes`` of a recording still being written); bytes past ``end`` are
        never read. See :attr:`report` afterwards."""
        self.report = rep = ReadReport()
        f = self._f
        off = self.data_offset if start is None else start
        size = self.size if end is None else min(end, self.size)
        f.seek(off)
        hsize = self._head.size
        while True:
            head = f.read(max(0, min(hsize, size - off)))
            if not head:
                return
            if len(head) == hsize and off + hsize <= size:
                magic, t_ns, mono_ns, length, crc = self._unpack(head)
                if magic == self._magic and length <= MAX_CHUNK and off + hsize + length <= size:
                    payload = f.read(length)
                    if len(payload) == length and self._crc(t_ns, mono_ns, payload) == crc:
                        rep.chunks += 1
                        rep.bytes += length
                        yield Chunk(t_ns, payload, off, mono_ns, hsize)
                        off += hsize + length
                        continue
            elif off + len(head) >= size:
                self._torn(off, rep, size)
                return
            # damaged chunk: hunt for the next chunk that validates
            nxt = self._resync(off + 1, size)
            if nxt is None:
                self._torn(off, rep, size)
                return
            rep.corrupt_chunks += 1
            rep.skipped_bytes += nxt - off
            rep.problems.append(f"damaged data at byte {off}: skipped {nxt - off} bytes")
            off = nxt
            f.seek(off)

    def _torn(self, off: int, rep: ReadReport, size: int) -> None:
        rep.torn_tail_bytes = size - off
        rep.problems.append(f"torn tail: last {size - off} bytes (an incomplete chunk) skipped")

    def _resync(self, start: int, size: int) -> int | None:
        """Offset of the next chunk at or after ``start`` whose CRC checks and which ends by
        ``size``, or None."""
        f = self._f
        pos = start
        window = 1 << 20
        while pos < size:
            f.seek(pos)
            buf = f.read(window + 3)
            i = buf.find(self._magic)
            while i >= 0:
                if self._valid_at(pos + i, size):
                    return pos + i
                i = buf.find(self._magic, i + 1)
            pos += window
        return None

    def _valid_at(self, off: int, size: int) -> bool:
        f = self._f
        f.seek(off)
        head = f.read(self._head.size)
        if len(head) < self._head.size:
            return False
        magic, t_ns, mono_ns, length, crc = self._unpack(head)
        if magic != self._magic or length > MAX_CHUNK or off + self._head.size + length > size:
            return False
        payload = f.read(length)
        return len(payload) == length and self._crc(t_ns, mono_ns, payload) == crc


def iter_prefix(path: str | os.PathLike[str], size: int, piece: int = 1 << 20) -> Iterator[bytes]:
    """The first ``size`` bytes of a file, in pieces: a snapshot of a recording still being
    written (``size`` = :attr:`RecordingWriter.committed_bytes` at request time), so a
    download's body always matches its Content-Length and is a prefix of the final file."""
    with open(path, "rb") as f:
        left = size
        while left > 0:
            b = f.read(min(piece, left))
            if not b:
                raise StorageError(f"{path}: shorter than its {size}-byte snapshot")
            left -= len(b)
            yield b


def iter_payloads(path: str | os.PathLike[str], chunk_bytes: int = 1 << 22,
                  progress: Callable[[int, int], None] | None = None,
                  report: ReadReport | None = None) -> Iterator[bytes]:
    """The received bytes of any input, in pieces of about ``chunk_bytes``, for decoding.

    A ``.rdrlog`` yields its payloads (small chunks coalesced); anything else is
    a raw capture read as is. ``progress(bytes_done, bytes_total)`` is called
    after each piece; a recording's read problems are added to ``report``.
    """
    if is_recording(path):
        with RecordingReader(path) as r:
            pending: list[bytes] = []
            size = 0
            for c in r:
                pending.append(c.data)
                size += len(c.data)
                if size >= chunk_bytes:
                    yield b"".join(pending)
                    pending, size = [], 0
                    if progress:
                        progress(c.offset, r.size)
            if pending:
                yield b"".join(pending)
            if progress:
                progress(r.size, r.size)
            if report is not None:
                for k in ("chunks", "bytes", "corrupt_chunks", "skipped_bytes", "torn_tail_bytes"):
                    setattr(report, k, getattr(report, k) + getattr(r.report, k))
                report.problems.extend(r.report.problems)
        return
    with open_input(path, "input", RecordingError) as f:
        total = os.fstat(f.fileno()).st_size
        done = 0
        while True:
            b = f.read(chunk_bytes)
            if not b:
                return
            done += len(b)
            yield b
            if progress:
                progress(done, total)
