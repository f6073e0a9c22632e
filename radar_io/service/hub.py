"""Websocket fan-out: one bounded queue per client, so a slow client never stalls anyone.

The reader thread publishes numbered messages with :meth:`Hub.publish_threadsafe`;
the event loop appends them to every client's queue. A full queue drops its
oldest *display* messages and counts them (the recording is never affected: it
was written by the reader thread before decoding). A client may ask for a
decimated stream (``max_hz``): it then gets the newest message at most that
often. A client that resumes with ``from=N`` first receives every message after
N still in the history, then the live stream, without duplicates.
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from typing import Any

from starlette.websockets import WebSocket

from radar_io.service.history import History


class Client:
    def __init__(self, ws: WebSocket, queue_size: int, max_hz: float | None) -> None:
        self.ws = ws
        self.queue: deque[tuple[int, str]] = deque()
        self.queue_size = queue_size
        self.min_interval = 1.0 / max_hz if max_hz else 0.0
        self.dropped = 0
        self.sent = 0
        self.last_sent = 0
        self.wake = asyncio.Event()

    def push(self, items: list[tuple[int, str]]) -> None:
        q = self.queue
        if self.min_interval:  # decimated: only the newest matters (events are all kept)
            events = [it for it in (*q, *items) if it[0] < 0]
            data = [it for it in items if it[0] >= 0]
            q.clear()
            q.extend(events)
            if data:
                q.append(data[-1])
        else:
            q.extend(items)
            over = len(q) - self.queue_size
            if over > 0:
                for _ in range(over):
                    q.popleft()
                self.dropped += over
        self.wake.set()

    async def _send(self, seq: int, text: str) -> None:
        if seq < 0:  # an event (alarm), outside the numbered history
            await self.ws.send({"type": "websocket.send", "text": text})
            return
        if seq <= self.last_sent:
            return
        await self.ws.send({"type": "websocket.send", "text": text})
        self.last_sent = seq
        self.sent += 1

    async def run(self, history: History, resume_after: int | None) -> None:
        if resume_after is not None:
            after = resume_after
            while True:  # backfill in slices; live messages keep queuing meanwhile
                items = history.since(after, 2000)
                if not items:
                    break
                for seq, _, text in items:
                    await self._send(seq, text)
                after = items[-1][0]
        while True:
            await self.wake.wait()
            self.wake.clear()
            q = self.queue
            while q:
                seq, text = q.popleft()
                await self._send(seq, text)
                if self.min_interval:
                    await asyncio.sleep(self.min_interval)


class Hub:
    """The set of live websocket clients."""

    def __init__(self, history: History, queue_size: int = 5000) -> None:
        self.history = history
        self.queue_size = queue_size
        self.clients: set[Client] = set()
        self.loop: asyncio.AbstractEventLoop | None = None
        self._dropped_closed = 0
        self.last_publish_mono = 0.0

    def attach(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop

    def publish_threadsafe(self, items: list[tuple[int, str]]) -> None:
        loop = self.loop
        if loop is not None and items and not loop.is_closed():
            loop.call_soon_threadsafe(self._dispatch, items)

    def publish_event_threadsafe(self, text: str) -> None:
        """Push one un-numbered message (e.g. an alarm) to every client; not in the history."""
        self.publish_threadsafe([(-1, text)])

    def _dispatch(self, items: list[tuple[int, str]]) -> None:
        self.last_publish_mono = time.monotonic()
        for c in self.clients:
            c.push(items)

    def register(self, ws: WebSocket, max_hz: float | None) -> Client:
        c = Client(ws, self.queue_size, max_hz)
        self.clients.add(c)
        return c

    def unregister(self, c: Client) -> None:
        if c in self.clients:
            self.clients.discard(c)
            self._dropped_closed += c.dropped

    @property
    def dropped(self) -> int:
        return self._dropped_closed + sum(c.dropped for c in self.clients)

    def stats(self) -> dict[str, Any]:
        return {"ws_clients": len(self.clients), "ws_dropped": self.dropped}
