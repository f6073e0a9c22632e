"""Expensive requests: a bounded number at once per kind, run away from the event loop and
from the default thread pool.

Reports, a recording's sync events, downloads and series queries can take seconds and
hundreds of MB each, and need no token. Each kind has a limit (config ``max_reports``,
``max_sync_queries``, ``max_downloads``, ``max_series_queries``); a request beyond it is
answered 429 at once with ``Retry-After`` (the kind's recent mean duration, rounded up).

The computing kinds (reports, sync events, series) run in worker **processes** (started
on first use, kept, at most as many as their limits together): a thread computing in
Python would hold the GIL half the time and the event loop, hence ``/api/status`` and
every control call, would wait for it (measured: status p99 0.8 s with four sync decodes
on threads). The workers run at nice 10, so acquisition and the event loop keep the CPU
first. Downloads only wait for the disk: they stream on a small thread pool of their
own. Neither is the default thread pool that the status, track and control routes use.

A worker that dies (killed for memory) fails its request with 503 and the next request
gets a fresh pool. A route uses it in one line (``fn`` and its arguments must pickle: a
module-level function of plain data)::

    return await state.limits.run("series", query_series, path, columns)
"""

from __future__ import annotations

import asyncio
import math
import multiprocessing
import os
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterator, Mapping
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

from fastapi import HTTPException
from starlette.responses import FileResponse, StreamingResponse
from starlette.types import Receive, Scope, Send

from radar_io.errors import UnavailableError

T = TypeVar("T")

#: the kinds and the config keys that bound them
KIND_KEYS = {"reports": "max_reports", "sync": "max_sync_queries",
             "downloads": "max_downloads", "series": "max_series_queries"}
#: kinds that compute (run in worker processes); the others stream (threads)
COMPUTING = frozenset({"reports", "sync", "series"})
#: Retry-After bounds (s)
RETRY_MIN_S, RETRY_MAX_S = 1, 60
#: worker processes' niceness: the reader thread and the event loop come first on the CPU
WORKER_NICE = 10


def _worker_init() -> None:
    os.nice(WORKER_NICE)


class ExpensiveLimiter:
    """Per-kind admission (429 + Retry-After beyond the limit) and the pools the work runs on."""

    def __init__(self, limits: Mapping[str, int]) -> None:
        self.limits = dict(limits)
        self._running = dict.fromkeys(self.limits, 0)
        self._refused = dict.fromkeys(self.limits, 0)
        self._mean_s = dict.fromkeys(self.limits, float(RETRY_MIN_S))
        self._lock = threading.Lock()  # released from pool threads, acquired on the loop
        self.pool = ThreadPoolExecutor(  # streaming kinds
            max_workers=max(1, sum(n for k, n in self.limits.items() if k not in COMPUTING)),
            thread_name_prefix="expensive")
        self._processes: ProcessPoolExecutor | None = None  # computing kinds, on first use

    def _executor(self, kind: str) -> Executor:
        if kind not in COMPUTING:
            return self.pool
        with self._lock:
            if self._processes is None:
                # spawn: the service has threads (reader, server), which fork would copy
                # in whatever state they were
                self._processes = ProcessPoolExecutor(
                    max_workers=sum(n for k, n in self.limits.items() if k in COMPUTING),
                    mp_context=multiprocessing.get_context("spawn"), initializer=_worker_init)
            return self._processes

    def acquire(self, kind: str) -> Callable[[], None]:
        """Take a slot of ``kind`` or raise HTTP 429 with Retry-After; returns its release
        (idempotent: call it when the work, or the response that streams it, is done)."""
        with self._lock:
            if self._running[kind] >= self.limits[kind]:
                self._refused[kind] += 1
                retry = min(RETRY_MAX_S, max(RETRY_MIN_S, math.ceil(self._mean_s[kind])))
                raise HTTPException(429, f"busy: {self._running[kind]} {kind} requests running "
                                    f"(at most {self.limits[kind]}); retry after {retry} s",
                                    headers={"Retry-After": str(retry)})
            self._running[kind] += 1
        t0 = time.monotonic()
        done = threading.Event()

        def release() -> None:
            with self._lock:
                if done.is_set():
                    return
                done.set()
                self._running[kind] -= 1
                self._mean_s[kind] += 0.3 * (time.monotonic() - t0 - self._mean_s[kind])

        return release

    async def run(self, kind: str, fn: Callable[..., T], *args: Any) -> T:
        """``fn(*args)`` within the limit of ``kind``, in a worker process for a computing
        kind. The slot is freed when the call ends, even if the client has gone."""
        release = self.acquire(kind)
        executor = self._executor(kind)
        try:  # submitted from a thread: it may start a worker process, which takes a moment
            fut = await asyncio.get_running_loop().run_in_executor(
                self.pool, executor.submit, fn, *args)
        except BaseException as exc:
            release()
            if isinstance(exc, BrokenProcessPool):
                self._drop(executor)
                raise UnavailableError(f"{kind}: the worker processes had died; try again") \
                    from exc
            raise
        fut.add_done_callback(lambda _f: release())
        try:
            return await asyncio.wrap_future(fut)
        except BrokenProcessPool as exc:  # killed (out of memory?): a new pool next time
            self._drop(executor)
            raise UnavailableError(f"{kind}: the worker process died (out of memory?)") from exc

    def _drop(self, executor: Executor) -> None:
        with self._lock:
            if self._processes is executor:
                self._processes = None
        executor.shutdown(wait=False, cancel_futures=True)

    def stats(self) -> dict[str, dict[str, int]]:
        """Per kind: ``running``, ``limit``, ``refused`` (429 so far)."""
        with self._lock:
            return {k: {"running": self._running[k], "limit": n, "refused": self._refused[k]}
                    for k, n in self.limits.items()}

    def close(self) -> None:
        """Stop the pools; worker processes still computing are terminated (their clients
        are gone with the service)."""
        self.pool.shutdown(wait=False, cancel_futures=True)
        procs = self._processes
        if procs is not None:
            workers = list(getattr(procs, "_processes", {}).values())  # no public API (3.11)
            procs.shutdown(wait=False, cancel_futures=True)
            for w in workers:
                w.terminate()


class _ReleasedWhenSent:
    """Mixin for a response that holds a limiter slot until it is sent (or the client left)."""

    release: Callable[[], None]

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)  # type: ignore[misc]
        finally:
            self.release()


class HeldFileResponse(_ReleasedWhenSent, FileResponse):
    """A file download holding a ``downloads`` slot while it is sent."""


class HeldStreamingResponse(_ReleasedWhenSent, StreamingResponse):
    """A stream holding a slot while it is sent."""


async def iterate_on(pool: ThreadPoolExecutor, it: Iterator[bytes]) -> AsyncIterator[bytes]:
    """The items of a blocking iterator, each fetched on ``pool`` (not the default pool)."""
    loop = asyncio.get_running_loop()
    end = object()
    try:
        while True:
            item = await loop.run_in_executor(pool, next, it, end)
            if item is end:
                return
            yield item  # type: ignore[misc]
    finally:
        close = getattr(it, "close", None)
        if close is not None:
            try:
                close()
            except ValueError:  # still running on the pool (client gone): closed when collected
                pass
