"""A sink on its own thread: ``submit`` never blocks the caller (acquisition).

The worker opens the sink on its thread, and when an open or a write fails on a sink
whose ``reopen`` is true, closes it and opens it again with back-off (0.1 s doubling
to 5 s; reset when a write succeeds). Batches that arrive while the sink is down or
the queue is full are dropped and counted, never queued without bound.
"""

from __future__ import annotations

import logging
import queue
import threading
from typing import Any

import numpy as np

from radar_io.errors import ValidationError
from radar_io.sinks.base import Sink

log = logging.getLogger("radar_io.sinks")

BACKOFF_START_S = 0.1
BACKOFF_MAX_S = 5.0


def message_columns(msgs: list[dict[str, Any]], names: list[str] | tuple[str, ...] | None = None
                    ) -> dict[str, np.ndarray]:
    """Message dicts → float64 columns (None → NaN); default: every non-string field."""
    first = msgs[0]
    if names is None:
        names = [k for k, v in first.items() if not isinstance(v, str)]
    return {c: np.array([np.nan if m[c] is None else m[c] for m in msgs], dtype=np.float64)
            for c in names if c in first}


class SinkWorker:
    """Runs one sink on its own thread through a bounded queue."""

    def __init__(self, name: str, sink: Sink, max_chunks: int = 2000) -> None:
        self.name, self.sink = name, sink
        self.q: queue.Queue[dict[str, np.ndarray] | None] = queue.Queue(max_chunks)
        self.dropped_samples = 0
        self.errors = 0
        self.reconnects = 0
        self.connected = False
        self.last_error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"sink-{name}", daemon=True)
        self._thread.start()

    def submit(self, msgs: list[dict[str, Any]]) -> None:
        """Snapshot the messages' columns (on the caller's thread) and queue them."""
        if msgs:
            self.submit_columns(message_columns(msgs))

    def submit_columns(self, cols: dict[str, np.ndarray]) -> None:
        """Queue a batch of columns (shared with other workers: sinks only read them)."""
        try:
            self.q.put_nowait(dict(cols))
        except queue.Full:
            self.dropped_samples += len(next(iter(cols.values()), ()))

    def _fail(self, exc: BaseException) -> None:
        self.errors += 1
        self.last_error = str(exc)
        if self.errors in (1, 10, 100) or self.errors % 1000 == 0:
            log.warning("%s sink: %s", self.name, exc)

    def _connect(self, backoff: float) -> float:
        """Open the sink, retrying with back-off until it opens or the worker stops; the
        back-off it ends with (reset to the start only by a successful write)."""
        while not self._stop.is_set():
            try:
                self.sink.open()
                self.connected = True
                return backoff
            except Exception as exc:  # noqa: BLE001 - any open failure is retried
                self._fail(exc)
                self._drain()
                if self._stop.wait(backoff):
                    break
                backoff = min(backoff * 2, BACKOFF_MAX_S)
        return backoff

    def _drain(self) -> None:
        """Drop (and count) what is queued while the sink is down."""
        while True:
            try:
                cols = self.q.get_nowait()
            except queue.Empty:
                return
            if cols is None:
                self._stop.set()
                return
            self.dropped_samples += len(next(iter(cols.values()), ()))

    def _run(self) -> None:
        backoff = self._connect(BACKOFF_START_S)
        while not self._stop.is_set():
            cols = self.q.get()
            if cols is None:
                break
            try:
                self.sink.write(cols)
                backoff = BACKOFF_START_S
            except ValidationError as exc:  # this batch cannot be encoded: the link is fine
                self._fail(exc)
                self.dropped_samples += len(next(iter(cols.values()), ()))
            except Exception as exc:  # noqa: BLE001 - a sink failure must not kill the worker
                self._fail(exc)
                if self.sink.reopen:
                    self.connected = False
                    self.sink.close()
                    self._drain()
                    if self._stop.wait(backoff):
                        break
                    self.reconnects += 1
                    backoff = self._connect(min(backoff * 2, BACKOFF_MAX_S))
        self.sink.close()
        self.connected = False

    def stats(self) -> dict[str, Any]:
        return {**self.sink.stats(), "connected": self.connected, "reconnects": self.reconnects,
                "dropped_samples": self.dropped_samples, "errors": self.errors,
                "last_error": self.last_error, "queued": self.q.qsize()}

    def close(self) -> None:
        self._stop.set()
        try:
            self.q.put_nowait(None)
        except queue.Full:
            pass
        self._thread.join(5)


def fan_out(workers: list[SinkWorker]) -> Any:
    """One acquisition processor for all ``workers``: the messages' columns are built once
    per read (on the reader thread) and queued to each worker."""
    def submit(msgs: list[dict[str, Any]]) -> None:
        if msgs and workers:
            cols = message_columns(msgs)
            for w in workers:
                w.submit_columns(cols)
    return submit
