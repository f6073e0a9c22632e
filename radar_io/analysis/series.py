"""Look back over whole recordings: a per-recording column store with a min/max pyramid.

``REC.rdrlog`` gets an index directory ``REC.series/`` beside it (format and rules in
docs/lookback.md):

* ``t_s.npy``: each frame's time, seconds since the recording's first chunk on the
  monotonic receive time (``mono_ns``); a frame is stamped with the receive time of the
  chunk that completed it, the live path's rule (never decreasing: a chunk whose time goes
  backwards, possible only in a version-1 file, keeps the time before it);
* ``COL.npy``: every decode column (plus runway / geodetic with a site, ``dy_m dz_m
  along_m leg`` with a reference path), one row per frame, in the decoder's dtype;
* ``COL.K.npy`` (K = 1, 2, …): the min/max pyramid, shape (rows_K, 2): row j of level K
  holds the min and max of rows [16 j, 16 j + 16) of level K - 1 (level 0 is the column
  itself), NaN (no value) skipped; only whole blocks are stored, so ``rows_K = rows_{K-1} //
  16`` and a level exists while it has a row;
* ``events.jsonl``: GO edges (``go``, ``edge`` rise / fall) and SYNC 0→1 edges
  (``sync``) found while indexing;
* ``manifest.json``: format, row count, column dtypes, the identity of what decoded it
  (spec, calibration, site, path), how far the recording was read and the state to go on
  from there (the framer's partial frame, the last GO / SYNC values).

An index is built in blocks (memory does not grow with the recording), kept up to date
for a recording still being written (new whole chunks appended), and rebuilt when it is
missing, damaged or stale (other calibration, site, path, spec or index format; a
recording that shrank or changed). A query reads at most ``2 × 16`` values per level per
bucket from memory-mapped files: never the whole range.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import logging
import math
import os
import shutil
import struct
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from radar_io.coordinates.reference_path import DEVIATION_COLUMNS, ReferencePath
from radar_io.coordinates.transforms import Site
from radar_io.decoding.biases import Calibration
from radar_io.errors import StorageError, ValidationError
from radar_io.wirespec.frame import FrameSpec

log = logging.getLogger("radar_io.series")
T = TypeVar("T")

#: index format; another value in a manifest means the index is rebuilt
FORMAT = "radar_io.series/2"
#: rows of one pyramid level per row of the next
FANOUT = 16
#: the index directory of ``X.rdrlog`` is ``X.series``
SUFFIX = ".series"
TIME_COLUMN = "t_s"
#: payload bytes read, framed and decoded per build step (about 87 000 RDR1 frames)
BLOCK_BYTES = 1 << 21
#: fixed size of every .npy header, so the row count can be rewritten in place on append
HEADER_BYTES = 128
#: recording bytes hashed to recognise the same recording again
HEAD_BYTES = 4096
#: event kinds found in the frames themselves (an event log's records of these are not used)
FRAME_EVENTS = ("go", "sync")


class IndexDamaged(Exception):
    """An index file is missing, truncated or does not match the manifest (rebuilt)."""


@dataclass(frozen=True)
class SeriesOptions:
    """What an index is decoded with: the live service's spec, calibration, site, path."""

    spec: FrameSpec
    calibration: Calibration = field(default_factory=Calibration)
    site: Site | None = None
    path: ReferencePath | None = None

    @property
    def columns(self) -> tuple[str, ...]:
        """The columns an index holds (``t_s`` aside), in decode order."""
        from radar_io.decoding.model import output_columns

        cols = output_columns(self.spec, self.site)
        return cols + DEVIATION_COLUMNS if self.path is not None else cols

    def identity(self) -> dict[str, Any]:
        """What makes an index of the same recording different: compared with the manifest."""
        cal = self.calibration
        site = None if self.site is None else {
            "name": self.site.name,
            "sha256": _sha(json.dumps(self.site.to_dict(), sort_keys=True).encode())}
        path = None
        if self.path is not None:
            p = self.path
            path = {"name": p.name, "frame": p.frame, "sha256": _sha(
                np.ascontiguousarray(p.points, dtype="<f8").tobytes()
                + repr(p.turn_radius_m).encode())}
        return {"spec_sha256": self.spec.sha256,
                "calibration": {"id": cal.id, "biases": [repr(float(cal.dsr_m)),
                                                         repr(float(cal.del_deg)),
                                                         repr(float(cal.daz_deg))]},
                "site": site, "path": path}


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# -- .npy files that grow ----------------------------------------------------------------
def _npy_header(dtype: np.dtype[Any], shape: tuple[int, ...]) -> bytes:
    """A version-1.0 NPY header of exactly :data:`HEADER_BYTES` bytes."""
    text = f"{{'descr': {dtype.str!r}, 'fortran_order': False, 'shape': {shape!r}, }}"
    body = text.ljust(HEADER_BYTES - 10 - 1) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(body)) + body.encode("latin1")


class _Growing:
    """One .npy file opened for appending rows after its first ``rows`` rows."""

    def __init__(self, path: Path, dtype: np.dtype[Any], width: int, rows: int) -> None:
        self.path, self.dtype, self.width, self.rows = path, dtype, width, rows
        self.f = open(path, "r+b" if path.exists() else "w+b")  # noqa: SIM115 - kept open
        self.f.seek(HEADER_BYTES + rows * width * dtype.itemsize)
        self.f.truncate()  # whatever an interrupted append left after the committed rows

    def append(self, a: np.ndarray) -> None:
        a = np.ascontiguousarray(a, dtype=self.dtype)
        self.f.write(a.data)
        self.rows += a.shape[0]

    def finish(self) -> None:
        """Write the header with the row count now held, close."""
        shape = (self.rows,) if self.width == 1 else (self.rows, self.width)
        self.f.seek(0)
        self.f.write(_npy_header(self.dtype, shape))
        self.f.close()

    def abandon(self) -> None:
        self.f.close()


def _load(path: Path, dtype: str, shape: tuple[int, ...]) -> np.ndarray:
    """An index file memory-mapped read-only, checked against the manifest."""
    try:
        a = np.load(path, mmap_mode="r" if math.prod(shape) else None, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise IndexDamaged(f"{path.name}: {exc}") from exc
    if a.dtype.str != dtype or a.shape != shape:
        raise IndexDamaged(f"{path.name}: {a.dtype.str} {a.shape}, manifest says {dtype} {shape}")
    return a


def level_rows(rows: int) -> list[int]:
    """Rows of level 0 (the column), 1, 2, … of the pyramid of a ``rows``-row column."""
    out = [rows]
    while out[-1] >= FANOUT:
        out.append(out[-1] // FANOUT)
    return out


# -- building ------------------------------------------------------------------------------
@dataclass
class _State:
    """Where indexing stands: what is needed to go on from the next chunk."""

    next_offset: int = 0
    t0_mono_ns: int | None = None
    t0_t_ns: int | None = None
    last_t_s: float = 0.0
    go: int = 0
    sync: int = 0
    tail: bytes = b""
    chunks: int = 0
    corrupt_chunks: int = 0


class _Writer:
    """Appends decoded blocks to an index directory: columns, pyramid, events."""

    def __init__(self, directory: Path, dtypes: dict[str, np.dtype[Any]], rows: int,
                 events: int, reserve_bytes: int) -> None:
        self.dir, self.dtypes, self.rows, self.events = directory, dtypes, rows, events
        self.reserve_bytes = reserve_bytes
        self.files: dict[tuple[str, int], _Growing] = {}
        self.carry: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self.row_bytes = sum(dt.itemsize for dt in dtypes.values()) * (FANOUT + 2) / FANOUT
        self._events = open(directory / "events.jsonl", "a+b")  # noqa: SIM115 - kept open
        try:
            self._open_files(events)
        except BaseException:
            self.abandon()
            raise

    def _open_files(self, events: int) -> None:
        directory, rows = self.dir, self.rows
        self._events.seek(0)
        for _ in range(events):
            if not self._events.readline().endswith(b"\n"):
                raise IndexDamaged(f"events.jsonl: fewer than {events} events")
        self._events.truncate()  # lines past the committed count: an interrupted append
        counts = level_rows(rows)
        for name, dt in self.dtypes.items():
            self.files[(name, 0)] = _Growing(directory / f"{name}.npy", dt, 1, rows)
            carry: list[tuple[np.ndarray, np.ndarray]] = []
            if name == TIME_COLUMN:
                self.carry[name] = carry
                continue
            for lvl, n in enumerate(counts):  # leftovers (< 16 rows) not yet in the next level
                done = n // FANOUT * FANOUT
                if lvl + 1 < len(counts):
                    self.files[(name, lvl + 1)] = _Growing(directory / f"{name}.{lvl + 1}.npy",
                                                           dt, 2, counts[lvl + 1])
                if lvl == 0:
                    v = np.array(_load(directory / f"{name}.npy", dt.str, (n,))[done:]) \
                        if n > done else np.empty(0, dt)
                    carry.append((v, v))
                else:
                    v = np.array(_load(directory / f"{name}.{lvl}.npy", dt.str, (n, 2))[done:]) \
                        if n > done else np.empty((0, 2), dt)
                    carry.append((v[:, 0].copy(), v[:, 1].copy()))
            self.carry[name] = carry

    def append(self, cols: dict[str, np.ndarray], events: list[dict[str, Any]]) -> None:
        n = len(cols[TIME_COLUMN])
        need = self.reserve_bytes + int(n * self.row_bytes)
        try:
            free = shutil.disk_usage(self.dir).free
        except OSError:
            free = None
        if free is not None and free < need:
            raise StorageError(f"look-back index {self.dir}: {free} bytes free, "
                               f"{need} needed (keeping {self.reserve_bytes} for recording)",
                               errno=errno.ENOSPC)
        try:
            for name in self.dtypes:
                v = cols[name]
                self.files[(name, 0)].append(v)
                if name != TIME_COLUMN:
                    self._push(name, 0, v, v)
            if events:
                self._events.write(b"".join(json.dumps(e).encode() + b"\n" for e in events))
        except OSError as exc:
            raise StorageError(f"cannot write look-back index {self.dir}: {exc.strerror}",
                               errno=exc.errno) from exc
        self.rows += n
        self.events += len(events)

    def _push(self, name: str, lvl: int, mins: np.ndarray, maxs: np.ndarray) -> None:
        """Add rows to level ``lvl``; the whole blocks of 16 go up to the next level."""
        carry = self.carry[name]
        if lvl == len(carry):
            carry.append((mins[:0], maxs[:0]))
        cm, cx = carry[lvl]
        if cm.size:
            same = mins is maxs  # level 0: one array for both
            mins = np.concatenate([cm, mins])
            maxs = mins if same else np.concatenate([cx, maxs])
        k = mins.size // FANOUT
        carry[lvl] = (mins[k * FANOUT:].copy(), maxs[k * FANOUT:].copy())
        if not k:
            return
        at = np.arange(0, k * FANOUT, FANOUT)
        up_min = np.fmin.reduceat(mins[:k * FANOUT], at)
        up_max = np.fmax.reduceat(maxs[:k * FANOUT], at)
        key = (name, lvl + 1)
        if key not in self.files:
            self.files[key] = _Growing(self.dir / f"{name}.{lvl + 1}.npy", self.dtypes[name], 2, 0)
        self.files[key].append(np.stack([up_min, up_max], axis=1))
        self._push(name, lvl + 1, up_min, up_max)

    def finish(self) -> None:
        """Every file's header written (the rows now held); the manifest comes next."""
        for f in self.files.values():
            f.finish()
        self._events.close()

    def abandon(self) -> None:
        for f in self.files.values():
            f.abandon()
        self._events.close()


class _Scanner:
    """Reads chunks, frames, decodes and stamps them, in blocks: the one build path."""

    def __init__(self, recording: Path, options: SeriesOptions, state: _State) -> None:
        from radar_io.decoding.batch_decoder import BatchDecoder
        from radar_io.framing.core import BatchFramer

        self.recording, self.options, self.state = recording, options, state
        self.framer = BatchFramer(options.spec)
        self.framer.feed_blocks(state.tail)  # back where the last scan stopped
        self.decoder = BatchDecoder(options.spec, options.calibration, options.site)
        self.seconds: dict[str, float] = {"read": 0.0, "frame": 0.0, "decode": 0.0,
                                          "deviation": 0.0, "write": 0.0}

    def run(self, writer: _Writer, end: int) -> None:
        from radar_io.recording.rdrlog import RecordingReader

        st = self.state
        t = time.perf_counter()
        with RecordingReader(self.recording) as r:
            if not st.next_offset:
                st.next_offset = r.data_offset
            payloads: list[bytes] = []
            mono: list[int] = []
            wall: list[int] = []
            size = 0
            for c in r.chunks(st.next_offset, end):
                if st.t0_mono_ns is None:
                    st.t0_mono_ns, st.t0_t_ns = c.mono_ns, c.t_ns
                payloads.append(c.data)
                mono.append(c.mono_ns)
                wall.append(c.t_ns)
                size += len(c.data)
                st.next_offset = c.offset + c.head_size + len(c.data)
                st.chunks += 1
                if size >= BLOCK_BYTES:
                    self.seconds["read"] += time.perf_counter() - t
                    self._block(writer, payloads, mono, wall)
                    payloads, mono, wall, size = [], [], [], 0
                    t = time.perf_counter()
            st.corrupt_chunks += r.report.corrupt_chunks
        self.seconds["read"] += time.perf_counter() - t
        if payloads:
            self._block(writer, payloads, mono, wall)
        st.tail = self.framer.pending_bytes

    def _block(self, writer: _Writer, payloads: list[bytes], mono: list[int],
               wall: list[int]) -> None:
        st, sec = self.state, self.seconds
        t = time.perf_counter()
        base = self.framer.stream_bytes
        ends: list[np.ndarray] = []
        blocks = self.framer.feed_blocks(b"".join(payloads), ends)
        if not blocks:
            sec["frame"] += time.perf_counter() - t
            return
        chunk_end = base + np.cumsum([len(p) for p in payloads], dtype=np.int64)
        # the chunk holding a frame's last byte completed it (the live path's time rule)
        ci = np.minimum(np.searchsorted(chunk_end, np.concatenate(ends), side="left"),
                        len(payloads) - 1)
        assert st.t0_mono_ns is not None
        t_s = (np.asarray(mono, dtype=np.int64)[ci] - st.t0_mono_ns) / 1e9
        np.maximum.accumulate(np.maximum(t_s, st.last_t_s), out=t_s)
        t_ns = np.asarray(wall, dtype=np.int64)[ci]
        t1 = time.perf_counter()
        sec["frame"] += t1 - t
        cols = self.decoder.decode(blocks)
        t2 = time.perf_counter()
        sec["decode"] += t2 - t1
        path = self.options.path
        if path is not None:
            cols.update(path.deviation(*(cols[c] for c in path.columns)))
        cols[TIME_COLUMN] = t_s
        events = self._events(cols, t_s, t_ns)
        t3 = time.perf_counter()
        sec["deviation"] += t3 - t2
        writer.append(cols, events)
        sec["write"] += time.perf_counter() - t3
        st.last_t_s = float(t_s[-1])

    def _events(self, cols: dict[str, np.ndarray], t_s: np.ndarray,
                t_ns: np.ndarray) -> list[dict[str, Any]]:
        """GO edges and SYNC 0→1 edges of a block, as the live path finds them."""
        st = self.state
        go = cols["go"].astype(np.int64)
        sync = cols["sync"].astype(np.int64)
        prev_go = np.concatenate([[st.go], go[:-1]])
        prev_sync = np.concatenate([[st.sync], sync[:-1]])
        st.go, st.sync = int(go[-1]), int(sync[-1])
        seq, tod = cols["seq"], cols["tod_s"]

        def event(i: int, kind: str, **extra: str) -> dict[str, Any]:
            return {"kind": kind, **extra, "t_s": float(t_s[i]), "t_ns": int(t_ns[i]),
                    "seq": int(seq[i]), "tod_s": float(tod[i])}

        found = [(i, 0, event(i, "go", edge="rise" if go[i] else "fall"))
                 for i in np.flatnonzero(go != prev_go).tolist()]
        found += [(i, 1, event(i, "sync"))
                  for i in np.flatnonzero((sync != 0) & (prev_sync == 0)).tolist()]
        return [e for _, _, e in sorted(found, key=lambda f: f[:2])]


# -- the index -----------------------------------------------------------------------------
_LOCKS: dict[Path, threading.Lock] = {}
_LOCKS_GUARD = threading.Lock()


@contextmanager
def _locked(recording: Path) -> Iterator[None]:
    """One index user at a time: a lock per recording for the threads of this process and
    ``flock`` on ``.X.series.lock`` for other processes (worker processes, a CLI)."""
    with _LOCKS_GUARD:
        lock = _LOCKS.setdefault(recording, threading.Lock())
    with lock:
        try:
            fd = os.open(recording.parent / f".{index_dir(recording).name}.lock",
                         os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise StorageError(f"cannot lock the look-back index of {recording}: "
                               f"{exc.strerror}", errno=exc.errno) from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            os.close(fd)  # releases the flock


def index_dir(recording: str | os.PathLike[str]) -> Path:
    """``X.series`` beside ``X.rdrlog``."""
    return Path(recording).with_suffix(SUFFIX)


class SeriesIndex:
    """The look-back index of one recording (checked, built, extended and opened under one
    lock per recording, across threads and processes).

    ``reserve_bytes``: free space the index never takes (the live recording's room); a
    build that would need it raises StorageError (ENOSPC) and leaves the old index.
    """

    def __init__(self, recording: str | os.PathLike[str], options: SeriesOptions,
                 reserve_bytes: int = 0) -> None:
        self.recording = Path(recording).resolve()
        self.dir = index_dir(self.recording)
        self.options = options
        self.reserve_bytes = reserve_bytes
        self._identity = options.identity()
        self._columns = options.columns
        #: what the last update did: "fresh", "built", "rebuilt", "appended"
        self.last_update = ""

    # -- queries ---------------------------------------------------------------------------
    def series(self, columns: Iterable[str], start_s: float | None = None,
               end_s: float | None = None, points: int = 1000,
               end: int | None = None) -> dict[str, Any]:
        """Min / max of ``columns`` over ``points`` equal buckets of [start_s, end_s]
        (seconds on the recording's time axis; None: its start / end; clamped to it), or
        each frame when the range holds at most ``points`` frames. ``end``: read the
        recording up to this file offset (the committed bytes of an open recording).

        Buckets are numpy.histogram's: ``[s + k w, s + (k + 1) w)`` with ``w = (e - s) /
        points``, the last one closed at ``e``. Values are float64, NaN where a bucket has
        no value (empty, or only null samples). Raises ValidationError for an unknown
        column or a bad range."""
        names = list(dict.fromkeys(columns))
        unknown = [c for c in names if c not in self._columns]
        if unknown:
            raise ValidationError(f"unknown column {unknown[0]!r}; columns are "
                                  f"{', '.join(self._columns)}")
        if not names:
            raise ValidationError("columns: give at least one column")
        if points < 1:
            raise ValidationError(f"points must be at least 1, got {points}")
        for what, v in (("start_s", start_s), ("end_s", end_s)):
            if v is not None and not math.isfinite(v):
                raise ValidationError(f"{what} must be a finite number, got {v}")
        if start_s is not None and end_s is not None and start_s > end_s:
            raise ValidationError(f"start_s {start_s} is after end_s {end_s}")
        _, (t, levels) = self._read(end, lambda man: self._open(man, names))
        return _answer(t, levels, start_s, end_s, points)

    def events(self, end: int | None = None) -> list[dict[str, Any]]:
        """GO edges (``go``, ``edge`` rise / fall) and SYNC 0→1 edges (``sync``) of the
        recording, found in its frames, with the other records of its event log
        ``X.events.jsonl`` (alarms, clock steps, annotations: ``kind``, ``t_ns``,
        ``mono_ns``) put on the same time axis; by time. The log's own ``go`` / ``sync``
        records are left out: the frames give them for any recording."""
        man, found = self._read(end, self._read_events)
        found += _event_log(self.recording.with_suffix(".events.jsonl"), man["recording"])
        found.sort(key=lambda e: (math.inf if e["t_s"] is None else e["t_s"]))
        return found

    def update(self, end: int | None = None) -> dict[str, Any]:
        """Build, rebuild or extend the index as needed; the manifest."""
        with _locked(self.recording):
            return self._update(end)

    def _read(self, end: int | None, read: Callable[[dict[str, Any]], T]
              ) -> tuple[dict[str, Any], T]:
        """The manifest of the index brought up to date and ``read(manifest)``, rebuilding
        the index once when ``read`` finds it damaged; under the lock."""
        with _locked(self.recording):
            man = self._update(end)
            try:
                return man, read(man)
            except IndexDamaged as exc:
                log.warning("look-back index of %s damaged (%s): rebuilt",
                            self.recording.name, exc)
                man = self._build(self._size(end), "rebuilt")
                return man, read(man)

    # -- keeping it fresh ------------------------------------------------------------------
    def _size(self, end: int | None) -> int:
        size = self.recording.stat().st_size
        return size if end is None else min(end, size)

    def _update(self, end: int | None) -> dict[str, Any]:
        size = self._size(end)
        man = self._manifest()
        if man is None:
            return self._build(size, "built" if not self.dir.exists() else "rebuilt")
        reason = self._stale(man, size)
        if reason:
            log.info("look-back index of %s is stale (%s): rebuilt", self.recording.name, reason)
            return self._build(size, "rebuilt")
        if size > man["recording"]["scanned_bytes"]:
            try:
                return self._extend(man, size)
            except IndexDamaged as exc:
                log.warning("look-back index of %s damaged (%s): rebuilt",
                            self.recording.name, exc)
                return self._build(size, "rebuilt")
        self.last_update = "fresh"
        return man

    def _manifest(self) -> dict[str, Any] | None:
        try:
            man = json.loads((self.dir / "manifest.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        ints = ("scanned_bytes", "next_offset", "chunks", "corrupt_chunks", "head_bytes")
        ok = (isinstance(man, dict) and isinstance(man.get("rows"), int)
              and isinstance(man.get("events"), int) and isinstance(man.get("columns"), dict)
              and isinstance(man.get("recording"), dict) and isinstance(man.get("resume"), dict)
              and all(isinstance(man["recording"].get(k), int) for k in ints))
        return man if ok else None

    def _stale(self, man: dict[str, Any], size: int) -> str:
        """Why the index cannot serve this recording as it now is ('' when it can)."""
        if man.get("format") != FORMAT or man.get("fanout") != FANOUT:
            return f"index format {man.get('format')!r}"
        if man.get("options") != self._identity:
            return "decoded with another calibration, site, path or spec"
        if list(man.get("columns", {})) != [*self._columns, TIME_COLUMN]:
            return "other columns"
        rec = man["recording"]
        if size < rec["scanned_bytes"]:
            return "the recording is shorter than what was indexed"
        if _head_sha(self.recording, rec["head_bytes"]) != rec["head_sha256"]:
            return "the recording's first bytes changed"
        return ""

    def _dtypes(self) -> dict[str, np.dtype[Any]]:
        """The dtype each column is stored in: the narrowest that holds every value the
        decoder can give it exactly (a word's values as float32 when its whole value
        table is exact in float32, 16-bit words as 16-bit integers), else the decoder's."""
        from radar_io.decoding.model import DecodeModel, value_table

        model = DecodeModel(self.options.spec, site=self.options.site)
        out: dict[str, np.dtype[Any]] = {c: np.dtype(model.dtype(c)) for c in self._columns
                                         if c in model.columns}
        for f in model.fields:
            if f.bits > 16 or f.column not in out:
                continue
            if model.is_scaled(f):
                table = value_table(f)
                if np.array_equal(table.astype(np.float32).astype(np.float64), table):
                    out[f.column] = np.dtype("<f4")
            elif out[f.column].kind in "iu":
                out[f.column] = np.dtype("<i2" if f.is_signed else "<u2")
        if self.options.path is not None:
            out.update(dy_m=np.dtype("<f8"), dz_m=np.dtype("<f8"), along_m=np.dtype("<f8"),
                       leg=np.dtype("<i4"))
        out[TIME_COLUMN] = np.dtype("<f8")
        return {c: out[c] for c in [*self._columns, TIME_COLUMN]}

    def _build(self, size: int, what: str) -> dict[str, Any]:
        """A new index in a temporary directory, swapped in when complete."""
        parent = self.dir.parent
        for pattern in (f".{self.dir.name}.tmp-*", f".{self.dir.name}.old-*"):
            for old in parent.glob(pattern):  # left by an interrupted build
                shutil.rmtree(old, ignore_errors=True)
        tmp = parent / f".{self.dir.name}.tmp-{uuid.uuid4().hex[:8]}"
        try:
            tmp.mkdir()
        except OSError as exc:
            raise StorageError(f"cannot create look-back index {tmp}: {exc.strerror}",
                               errno=exc.errno) from exc
        try:
            t, cpu = time.perf_counter(), time.thread_time()
            state = _State()
            man = self._scan(tmp, state, self._dtypes(), 0, 0, size)
            man["build_s"] = {**man.pop("scan_s"), "total": time.perf_counter() - t,
                              "cpu": time.thread_time() - cpu}
            self._write_manifest(tmp, man)
            if self.dir.exists():
                old = parent / f".{self.dir.name}.old-{uuid.uuid4().hex[:8]}"
                os.rename(self.dir, old)
                os.rename(tmp, self.dir)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.rename(tmp, self.dir)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        self.last_update = what
        log.info("look-back index of %s %s: %d frames in %.2f s", self.recording.name, what,
                 man["rows"], man["build_s"]["total"])
        return man

    def _extend(self, man: dict[str, Any], size: int) -> dict[str, Any]:
        """Index the chunks added since the last scan (a recording still being written)."""
        rec, resume = man["recording"], man["resume"]
        state = _State(next_offset=rec["next_offset"], t0_mono_ns=rec["t0_mono_ns"],
                       t0_t_ns=rec["t0_t_ns"], last_t_s=resume["last_t_s"], go=resume["go"],
                       sync=resume["sync"], tail=bytes.fromhex(resume["tail"]),
                       chunks=rec["chunks"], corrupt_chunks=rec["corrupt_chunks"])
        dtypes = {c: np.dtype(d) for c, d in man["columns"].items()}
        new = self._scan(self.dir, state, dtypes, man["rows"], man["events"], size)
        new["build_s"] = man.get("build_s", {})
        new.pop("scan_s")
        self._write_manifest(self.dir, new)
        self.last_update = "appended"
        return new

    def _scan(self, directory: Path, state: _State, dtypes: dict[str, np.dtype[Any]],
              rows: int, events: int, size: int) -> dict[str, Any]:
        try:
            writer = _Writer(directory, dtypes, rows, events, self.reserve_bytes)
        except OSError as exc:
            raise StorageError(f"cannot open look-back index {directory}: {exc.strerror}",
                               errno=exc.errno) from exc
        scanner = _Scanner(self.recording, self.options, state)
        try:
            scanner.run(writer, size)
            t = time.perf_counter()
            writer.finish()
            scanner.seconds["write"] += time.perf_counter() - t
        except BaseException:
            writer.abandon()
            raise
        head = min(size, HEAD_BYTES)
        return {
            "format": FORMAT, "fanout": FANOUT, "rows": writer.rows, "events": writer.events,
            "columns": {c: dt.str for c, dt in dtypes.items()},
            "options": self._identity,
            "recording": {"name": self.recording.name, "scanned_bytes": size,
                          "next_offset": state.next_offset, "chunks": state.chunks,
                          "corrupt_chunks": state.corrupt_chunks,
                          "head_bytes": head, "head_sha256": _head_sha(self.recording, head),
                          "t0_mono_ns": state.t0_mono_ns, "t0_t_ns": state.t0_t_ns},
            "resume": {"tail": state.tail.hex(), "go": state.go, "sync": state.sync,
                       "last_t_s": state.last_t_s},
            "scan_s": scanner.seconds,
        }

    @staticmethod
    def _write_manifest(directory: Path, man: dict[str, Any]) -> None:
        tmp = directory / "manifest.json.tmp"
        try:
            tmp.write_text(json.dumps(man, indent=1), encoding="utf-8")
            os.replace(tmp, directory / "manifest.json")
        except OSError as exc:
            raise StorageError(f"cannot write look-back index {directory}: {exc.strerror}",
                               errno=exc.errno) from exc

    def _open(self, man: dict[str, Any], names: list[str]
              ) -> tuple[np.ndarray, dict[str, list[np.ndarray]]]:
        rows = man["rows"]
        try:
            dtypes = {c: man["columns"][c] for c in [*names, TIME_COLUMN]}
        except KeyError as exc:
            raise IndexDamaged(f"manifest has no column {exc}") from exc
        t = _load(self.dir / f"{TIME_COLUMN}.npy", dtypes[TIME_COLUMN], (rows,))
        counts = level_rows(rows)
        levels = {}
        for c in names:
            levels[c] = [_load(self.dir / f"{c}.npy", dtypes[c], (rows,))] + [
                _load(self.dir / f"{c}.{k}.npy", dtypes[c], (n, 2))
                for k, n in enumerate(counts[1:], start=1)]
        return t, levels

    def _read_events(self, man: dict[str, Any]) -> list[dict[str, Any]]:
        out = []
        try:
            with open(self.dir / "events.jsonl", encoding="utf-8") as f:
                for _ in range(man["events"]):
                    out.append(json.loads(f.readline()))
        except (OSError, ValueError) as exc:
            raise IndexDamaged(f"events.jsonl: {exc}") from exc
        return out


def query_series(recording: str | os.PathLike[str], options: SeriesOptions,
                 columns: list[str], start_s: float | None = None, end_s: float | None = None,
                 points: int = 1000, end: int | None = None,
                 reserve_bytes: int = 0) -> dict[str, Any]:
    """:meth:`SeriesIndex.series` as one call of plain, picklable data (for a worker
    thread or process)."""
    return SeriesIndex(recording, options, reserve_bytes).series(columns, start_s, end_s,
                                                                 points, end=end)


def query_events(recording: str | os.PathLike[str], options: SeriesOptions,
                 end: int | None = None, reserve_bytes: int = 0) -> list[dict[str, Any]]:
    """:meth:`SeriesIndex.events` as one call of plain, picklable data."""
    return SeriesIndex(recording, options, reserve_bytes).events(end=end)


def _head_sha(path: Path, n: int) -> str:
    with open(path, "rb") as f:
        return _sha(f.read(n))


def _event_log(path: Path, rec: dict[str, Any]) -> list[dict[str, Any]]:
    """Records of a recording's event log on its time axis: ``mono_ns`` when the record has
    it, else its wall-clock ``t_ns`` (or Unix ``t_s``) against the first chunk's."""
    t0_mono, t0_wall = rec.get("t0_mono_ns"), rec.get("t0_t_ns")
    out: list[dict[str, Any]] = []
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            lines = f.readlines()
    except FileNotFoundError:
        return out
    except OSError as exc:
        log.warning("event log %s: %s", path, exc.strerror)
        return out
    bad = 0
    for line in lines:
        try:
            r = json.loads(line)
        except ValueError:
            r = None
        if not isinstance(r, dict):
            bad += 1
            continue
        kind = r.get("kind", r.get("type"))
        t_ns, mono = r.get("t_ns"), r.get("mono_ns")
        if not isinstance(t_ns, int) and isinstance(r.get("t_s"), (int, float)):
            t_ns = round(r["t_s"] * 1e9)  # the alarm log's Unix seconds
        if not isinstance(kind, str) or not isinstance(t_ns, int):
            bad += 1
            continue
        if kind in FRAME_EVENTS:
            continue
        if isinstance(mono, int) and t0_mono is not None:
            t_s: float | None = (mono - t0_mono) / 1e9
        elif t0_wall is not None:
            t_s = (t_ns - t0_wall) / 1e9
        else:
            t_s = None
        clean = {k: None if isinstance(v, float) and not math.isfinite(v) else v
                 for k, v in r.items()}
        out.append({**clean, "kind": kind, "t_s": t_s, "t_ns": t_ns})
    if bad:
        log.warning("event log %s: %d line(s) without kind and t_ns skipped", path, bad)
    return out


# -- answering -----------------------------------------------------------------------------
def _answer(t: np.ndarray, levels: dict[str, list[np.ndarray]], start_s: float | None,
            end_s: float | None, points: int) -> dict[str, Any]:
    n = t.shape[0]
    if n == 0:
        return {"start_s": 0.0, "end_s": 0.0, "decimated": False, "frames": 0, "t_s": [],
                "columns": {c: {"min": [], "max": []} for c in levels}}
    last = float(t[-1])
    s = 0.0 if start_s is None else min(max(start_s, 0.0), last)
    e = last if end_s is None else min(max(end_s, 0.0), last)
    i0 = int(np.searchsorted(t, s, side="left"))
    i1 = int(np.searchsorted(t, e, side="right"))
    out: dict[str, Any] = {"start_s": s, "end_s": e, "frames": i1 - i0}
    if i1 - i0 <= points:
        out.update(decimated=False, t_s=_json_floats(np.asarray(t[i0:i1])))
        cols = {}
        for c, lv in levels.items():
            v = _json_floats(np.asarray(lv[0][i0:i1], dtype=np.float64))
            cols[c] = {"min": v, "max": v}
        out["columns"] = cols
        return out
    edges = np.minimum(s + np.arange(points) * ((e - s) / points), e)
    idx = np.empty(points + 1, dtype=np.int64)
    idx[:-1] = np.searchsorted(t, edges, side="left")
    idx[-1] = i1
    out.update(decimated=True, t_s=edges.tolist())
    cols = {}
    for c, lv in levels.items():
        mn, mx = range_min_max(lv, idx[:-1], idx[1:])
        cols[c] = {"min": _json_floats(mn), "max": _json_floats(mx)}
    out["columns"] = cols
    return out


def _json_floats(a: np.ndarray) -> list[float | None]:
    """A float64 array as a JSON-ready list, NaN (no value) as None."""
    out: list[float | None] = a.tolist()
    for i in np.flatnonzero(~np.isfinite(a)).tolist():
        out[i] = None
    return out


def range_min_max(levels: list[np.ndarray], a: np.ndarray, b: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Min and max (float64, NaN skipped; NaN for an empty range) of rows [a_k, b_k) of a
    column, from its pyramid ``levels`` (level 0: the column; level K: (rows_K, 2) min/max
    of blocks of 16**K rows). Each range is split into whole blocks of the coarsest level
    that fits and fewer than 16 elements of each finer level at either end, so at most
    2 × 15 values per level and range are read."""
    mn = np.full(a.shape, np.nan)
    mx = np.full(a.shape, np.nan)
    a, b = a.astype(np.int64), b.astype(np.int64)
    active = a < b
    for lvl, arr in enumerate(levels):
        if lvl + 1 == len(levels):  # coarsest level: the rest of each range
            _reduce(arr, lvl, np.where(active, a, 0), np.where(active, b, 0), mn, mx)
            break
        au, bu = -(-a // FANOUT), b // FANOUT
        up = active & (au < bu)          # holds a whole block of the next level
        whole = active & ~up             # does not: all of it at this level
        _reduce(arr, lvl, np.where(active, a, 0),
                np.where(up, au * FANOUT, np.where(whole, b, 0)), mn, mx)
        _reduce(arr, lvl, np.where(up, bu * FANOUT, 0), np.where(up, b, 0), mn, mx)
        a, b, active = au, bu, up
        if not active.any():
            break
    return mn, mx


def _reduce(arr: np.ndarray, lvl: int, s: np.ndarray, e: np.ndarray, mn: np.ndarray,
            mx: np.ndarray) -> None:
    """Fold the min / max of rows [s_k, e_k) of one level into ``mn`` / ``mx``."""
    length = e - s
    k = np.flatnonzero(length > 0)
    if not k.size:
        return
    length = length[k]
    at = np.zeros(k.size, dtype=np.int64)
    np.cumsum(length[:-1], out=at[1:])
    rows = np.repeat(s[k] - at, length) + np.arange(int(at[-1] + length[-1]))
    if lvl == 0:
        lo = hi = np.asarray(arr[rows], dtype=np.float64)
    else:
        got = np.asarray(arr[rows], dtype=np.float64)
        lo, hi = got[:, 0], got[:, 1]
    mn[k] = np.fmin(mn[k], np.fmin.reduceat(lo, at))
    mx[k] = np.fmax(mx[k], np.fmax.reduceat(hi, at))
