"""Websocket fan-out: each message encoded once and shared; a slow client never stalls anyone.

The reader thread publishes numbered messages (``(msg_seq, json_text)``, encoded once
by the history) with :meth:`Hub.publish_threadsafe`; they are gathered and handed to
every client every ``interval_s`` as one shared :class:`Block`. A client's queue is
bounded in messages: beyond it the oldest blocks are skipped (counted in ``dropped``;
the recording is never affected: it was written by the reader thread before decoding).

Per client: ``batch`` clients receive one JSON array per block (the array text is built
once per block, shared by all of them; when several blocks wait because the loop is
busy, they go as one frame, so a loaded server sends fewer, larger frames); the others one
message per websocket frame;
``max_hz`` clients get the newest message at most that often. A client that resumes
with ``from=N`` first receives every message after N still in the history, then the
live stream, without duplicates.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections import deque
from typing import Any

from starlette.websockets import WebSocket

from radar_io.service.history import History

#: a one-message-per-frame client yields to the loop after this many sends
YIELD_EVERY = 16


class Block:
    """Messages published together: shared, immutable, the array text built once."""

    __slots__ = ("_array", "first", "items", "last")

    def __init__(self, items: list[tuple[int, str]]) -> None:
        self.items = items
        self.first, self.last = items[0][0], items[-1][0]
        self._array: str | None = None

    @property
    def array(self) -> str:
        """The block as one JSON array text (built on first use, then shared)."""
        if self._array is None:
            self._array = "[" + ",".join(t for _, t in self.items) + "]"
        return self._array


class Client:
    def __init__(self, ws: WebSocket, queue_size: int, max_hz: float | None,
                 batch: bool = False) -> None:
        self.ws = ws
        self.queue: deque[Block] = deque()
        self.queued = 0
        self.queue_size = queue_size
        self.min_interval = 1.0 / max_hz if max_hz else 0.0
        self.batch = batch
        self.dropped = 0
        self.sent = 0
        self.last_sent = 0
        self.wake = asyncio.Event()

    def push(self, block: Block) -> None:
        """Queue a block (event-loop thread); skip the oldest beyond ``queue_size`` messages."""
        q = self.queue
        if block.first < 0:  # an event (alarm): always queued, never decimated
            q.append(block)
            self.queued += len(block.items)
        elif self.min_interval:  # decimated: only the newest matters (queued events stay)
            events = [b for b in q if b.first < 0]
            q.clear()
            q.extend(events)
            q.append(Block([block.items[-1]]))
            self.queued = len(events) + 1
        else:
            q.append(block)
            self.queued += len(block.items)
            while self.queued > self.queue_size and len(q) > 1:
                old = q.popleft()
                self.queued -= len(old.items)
                self.dropped += len(old.items)
        self.wake.set()

    async def _send_text(self, text: str) -> None:
        await self.ws.send({"type": "websocket.send", "text": text})

    async def _send_items(self, items: list[tuple[int, str]]) -> None:
        items = [it for it in items if it[0] > self.last_sent]
        if not items:
            return
        if self.batch:
            await self._send_text("[" + ",".join(t for _, t in items) + "]")
            self.last_sent = items[-1][0]
            self.sent += len(items)
            return
        for k, (seq, text) in enumerate(items):
            await self._send_text(text)
            self.last_sent = seq
            self.sent += 1
            if k % YIELD_EVERY == YIELD_EVERY - 1:
                await asyncio.sleep(0)  # a send that does not block never yields: take turns
                if self.queued > self.queue_size:  # fallen behind meanwhile: skip ahead
                    return

    async def _send_block(self, b: Block) -> None:
        if b.first < 0:  # an event, outside the numbered history: one text frame each
            for _, text in b.items:
                await self._send_text(text)
            return
        if b.last <= self.last_sent:
            return
        if b.first <= self.last_sent or not self.batch:  # overlaps the backfill / one by one
            await self._send_items(b.items)
            return
        await self._send_text(b.array)  # the shared text
        self.last_sent = b.last
        self.sent += len(b.items)

    async def _send_blocks(self, blocks: list[Block]) -> None:
        """Batch client, several blocks waiting (the loop is busy): one frame for all of them,
        joined from the shared array texts, so the sends per second fall as load rises."""
        blocks = [b for b in blocks if b.last > self.last_sent]
        if not blocks:
            return
        if blocks[0].first <= self.last_sent:  # overlaps the backfill: per message
            await self._send_items([it for b in blocks for it in b.items])
            return
        await self._send_text("[" + ",".join(b.array[1:-1] for b in blocks) + "]")
        self.last_sent = blocks[-1].last
        self.sent += sum(len(b.items) for b in blocks)

    async def run(self, history: History, resume_after: int | None) -> None:
        if resume_after is not None:
            after = resume_after
            while True:  # backfill in slices; live messages keep queuing meanwhile
                items = history.since(after, 2000)
                if not items:
                    break
                await self._send_items(items)
                after = items[-1][0]
        while True:
            await self.wake.wait()
            self.wake.clear()
            q = self.queue
            if self.batch and len(q) > 1:
                blocks = list(q)
                q.clear()
                self.queued = 0
                await self._send_blocks(blocks)
                continue
            while q:
                b = q.popleft()
                self.queued -= len(b.items)
                await self._send_block(b)
                if self.min_interval:
                    await asyncio.sleep(self.min_interval)


class Hub:
    """The set of live websocket clients and the shared fan-out tick."""

    def __init__(self, history: History, queue_size: int = 5000, max_clients: int = 500,
                 interval_s: float = 0.01) -> None:
        self.history = history
        self.queue_size = queue_size
        self.max_clients = max_clients
        self.interval_s = interval_s
        self.clients: set[Client] = set()
        self.loop: asyncio.AbstractEventLoop | None = None
        self.refused = 0
        self.undispatched = 0  #: messages dropped before dispatch (loop overloaded)
        self.max_pending = max(10 * queue_size, 20000)
        self._dropped_closed = 0
        self._pending: list[tuple[int, str]] = []
        self._lock = threading.Lock()
        self._scheduled = False
        self.last_publish_mono = 0.0

    def attach(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop

    def publish_threadsafe(self, items: list[tuple[int, str]]) -> None:
        """From the reader thread: gather; one dispatch per ``interval_s`` on the loop."""
        loop = self.loop
        if loop is None or not items or loop.is_closed():
            return
        with self._lock:
            self._pending.extend(items)
            over = len(self._pending) - self.max_pending
            if over > 0:  # the loop is not dispatching (overloaded): keep the newest only
                del self._pending[:over]
                self.undispatched += over
            if self._scheduled:
                return
            self._scheduled = True
        try:
            if self.interval_s > 0:
                loop.call_soon_threadsafe(loop.call_later, self.interval_s, self._dispatch)
            else:
                loop.call_soon_threadsafe(self._dispatch)
        except RuntimeError:  # loop closing at shutdown
            pass

    def publish_event_threadsafe(self, text: str) -> None:
        """Push one un-numbered message (an alarm) to every client at once; not in the
        history, never decimated. Any thread."""
        loop = self.loop
        if loop is None or loop.is_closed():
            return
        try:
            loop.call_soon_threadsafe(self._dispatch_event, text)
        except RuntimeError:  # loop closing at shutdown
            pass

    def _dispatch_event(self, text: str) -> None:
        block = Block([(-1, text)])
        for c in self.clients:
            c.push(block)

    def _dispatch(self) -> None:
        with self._lock:
            items, self._pending = self._pending, []
            self._scheduled = False
        if not items:
            return
        self.last_publish_mono = time.monotonic()
        block = Block(items)
        for c in self.clients:
            c.push(block)

    def full(self) -> bool:
        return len(self.clients) >= self.max_clients

    def register(self, ws: WebSocket, max_hz: float | None, batch: bool = False) -> Client:
        c = Client(ws, self.queue_size, max_hz, batch)
        self.clients.add(c)
        return c

    def unregister(self, c: Client) -> None:
        if c in self.clients:
            self.clients.discard(c)
            self._dropped_closed += c.dropped

    @property
    def dropped(self) -> int:
        clients = tuple(self.clients)  # other threads read this while the loop adds clients
        return self._dropped_closed + sum(c.dropped for c in clients) + \
            self.undispatched * len(clients)

    def stats(self) -> dict[str, Any]:
        return {"ws_clients": len(self.clients), "ws_dropped": self.dropped,
                "ws_refused": self.refused, "history_messages": len(self.history),
                "history_bytes": self.history.nbytes}
