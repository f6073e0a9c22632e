"""``replay://PATH.rdrlog?speed=1.0``: a recording played back as a byte source.

Paced by the recorded monotonic receive times (``mono_ns``; a version-1 file has only the
wall-clock ``t_ns``, used in its place), so a wall-clock step during the recording neither
stalls the replay nor moves a seek (``speed`` multiplies the pace, ``0`` = as
fast as possible), with pause, resume, seek, step and speed for the service's replay
controls. The same class serves ``radar-io serve --source replay://…`` (the ground replay
that drives the outputs) and the service's replay sessions (``service/sessions.py``)."""

from __future__ import annotations

import threading
import time
import urllib.parse
from pathlib import Path
from typing import Any

from radar_io.errors import SourceError
from radar_io.recording.rdrlog import RecordingReader
from radar_io.sources.base import parse_query


class ReplaySource:
    """A ``.rdrlog`` as a :class:`~radar_io.sources.base.ByteSource`, paced by its receive timestamps.

    ``speed`` multiplies the recorded pace (``0`` = as fast as possible). Step
    delivers the next recorded chunk (one read of the original port) while paused.

    After a :meth:`seek` the next bytes do not follow the previous ones: the read that
    delivers them sets :attr:`discontinuous`, and the pipeline then resets its framer
    and edge state (no SEQ gap, no sync / GO edge counted across the jump).

    ``size_bytes`` limits the replay to the chunks that end within the file's first
    ``size_bytes`` (a recording still being written: its committed bytes). Each read that
    returns data sets :attr:`last_t_ns` and :attr:`last_mono_ns` to that chunk's recorded
    receive times.
    """

    def __init__(self, path: Path, speed: float = 1.0, size_bytes: int | None = None) -> None:
        if speed < 0:
            raise SourceError("replay speed must be >= 0")
        self.path = Path(path)
        self.url = f"replay://{self.path.name}?speed={speed:g}"
        with RecordingReader(self.path) as r:
            self.header = r.header
            # (payload offset, monotonic receive time, length, wall-clock receive time)
            self._index = []
            for c in r:
                end = c.offset + c.head_size + len(c.data)
                if size_bytes is not None and end > size_bytes:
                    break
                self._index.append((c.offset + c.head_size, c.mono_ns, len(c.data), c.t_ns))
            self.report = r.report
        self.last_t_ns = 0     #: recorded wall-clock receive time of the last chunk read (ns)
        self.last_mono_ns = 0  #: recorded monotonic receive time of the last chunk read (ns)
        self._lock = threading.Lock()
        self.speed = speed
        self.paused = False
        self._steps = 0
        self._i = 0
        self._anchor: tuple[float, int] | None = None  # (monotonic now, recorded mono_ns)
        self._f: Any = None
        self._jumped = False        #: a seek happened since the last delivered chunk
        self.discontinuous = False  #: the last read()'s bytes do not follow the previous read's
        self.seeks = 0

    @property
    def duration_s(self) -> float:
        if not self._index:
            return 0.0
        return (self._index[-1][1] - self._index[0][1]) / 1e9

    @property
    def finished(self) -> bool:
        return self._i >= len(self._index)

    def state(self) -> dict[str, Any]:
        with self._lock:
            pos = (self._index[min(self._i, len(self._index) - 1)][1] - self._index[0][1]) / 1e9 \
                if self._index else 0.0
            return {"recording": self.path.stem, "speed": self.speed, "paused": self.paused,
                    "position_s": pos, "duration_s": self.duration_s, "finished": self.finished,
                    "chunk": self._i, "chunks": len(self._index)}

    def open(self) -> None:
        try:
            self._f = open(self.path, "rb")  # noqa: SIM115 - held until close()
        except OSError as exc:
            raise SourceError(f"cannot open recording {self.path.name}: {exc.strerror}") from exc
        self._anchor = None
        self._jumped = self.discontinuous = False

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def pause(self) -> None:
        with self._lock:
            self.paused = True

    def resume(self) -> None:
        with self._lock:
            self.paused = False
            self._anchor = None

    def step(self, n: int = 1) -> None:
        with self._lock:
            self.paused = True
            self._steps += max(1, n)

    def set_speed(self, speed: float) -> None:
        if speed < 0:
            raise SourceError("replay speed must be >= 0")
        with self._lock:
            self.speed = speed
            self._anchor = None

    def seek(self, position_s: float) -> None:
        """Jump to the first chunk received at or after ``position_s`` from the start."""
        with self._lock:
            if not self._index:
                return
            t = self._index[0][1] + int(max(0.0, position_s) * 1e9)
            lo, hi = 0, len(self._index)
            while lo < hi:
                mid = (lo + hi) // 2
                if self._index[mid][1] < t:
                    lo = mid + 1
                else:
                    hi = mid
            self._i = lo
            self._anchor = None
            self._jumped = True
            self.seeks += 1

    def read(self, timeout_s: float) -> bytes:
        if self._f is None:
            raise SourceError(f"{self.url} is not open")
        with self._lock:
            if self.finished or (self.paused and not self._steps):
                wait = timeout_s
                entry = None
            else:
                entry = self._index[self._i]
                stepping = self.paused
                wait = 0.0
                if not stepping and self.speed > 0:
                    if self._anchor is None:
                        self._anchor = (time.monotonic(), entry[1])
                    due = self._anchor[0] + (entry[1] - self._anchor[1]) / 1e9 / self.speed
                    wait = due - time.monotonic()
                if wait <= 0:
                    self._i += 1
                    if stepping:
                        self._steps -= 1
                    self.discontinuous, self._jumped = self._jumped, False
        if entry is None or wait > 0:
            time.sleep(min(max(wait, 0.0), timeout_s))
            return b""
        off, mono_ns, length, t_ns = entry
        try:
            self._f.seek(off)
            data = self._f.read(length)
        except OSError as exc:
            raise SourceError(f"reading recording {self.path.name}: {exc.strerror}") from exc
        if len(data) != length:
            raise SourceError(f"recording {self.path.name} changed under the replay")
        self.last_t_ns, self.last_mono_ns = t_ns, mono_ns
        return data


def replay_from_url(url: str) -> ReplaySource:
    """``replay://PATH?speed=S`` → a :class:`ReplaySource` (not yet opened)."""
    parts, q = parse_query(url)
    path = urllib.parse.unquote(parts.netloc + parts.path)
    if not path:
        raise SourceError(f"{url}: no recording path")
    try:
        speed = float(q.get("speed", "1.0"))
    except ValueError as exc:
        raise SourceError(f"{url}: speed must be a number") from exc
    return ReplaySource(Path(path), speed)
