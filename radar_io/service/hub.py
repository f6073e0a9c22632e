"""Websocket fan-out: each message encoded once and shared; a slow client never stalls anyone.

The reader thread publishes numbered messages (``(msg_seq, json_text)``, encoded once
by the history) with :meth:`Hub.publish_threadsafe`. **Adaptive batching**: the first
message after a dispatch schedules one dispatch on the event loop
(``call_soon_threadsafe``); everything gathered until the loop runs it goes to every
client as one shared :class:`Block`. An idle loop dispatches each read at once; a busy
loop dispatches less often, in larger blocks, and so do many ``batch=1`` clients
(dispatches are :data:`SPACING_PER_BATCH_CLIENT_S` apart per full-rate batch client
beyond the first few). ``interval_s`` > 0 sets a longer minimum spacing (``ws_batch_interval_s``; 0, the
default, is adaptive).

**Turns** (:class:`SendTurns`, one per event loop, shared by every hub on it): a client
sends at most :data:`QUANTUM` frames per turn, and the turns taken in one loop iteration
hold at most :data:`ROUND_SENDS` frames; clients beyond wait, first come first served,
for a later iteration. Between iterations the loop serves HTTP (``/api/status``,
control), so a heavy fan-out delays a request by about one round, not by every
client's backlog. A client's queue is bounded in messages (``queue_size``): beyond it
the oldest blocks are skipped, and a one-message-per-frame client more than
:data:`MAX_LAG_S` behind skips ahead to the newest block (both counted in ``dropped``; the
recording is never affected: it was written by the reader thread before decoding).

Per client: ``batch`` clients receive one JSON array per turn (one block's array text is
built once and shared by all of them; several waiting blocks are joined into one frame,
so a loaded server sends fewer, larger frames); the others one message per websocket
frame; ``max_hz`` clients get the newest message at most that often. A client that
resumes with ``from=N`` first receives every message after N still in the history, then
the live stream, without duplicates.

**State messages** (:meth:`Hub.publish_event_threadsafe`, the alarm list) are outside
the numbered history and never decimated, but only the newest of each kind waits in a
client's queue: a newer one replaces it (the message carries the whole state).
"""

from __future__ import annotations

import asyncio
import threading
import time
import weakref
from collections import deque
from typing import Any

from starlette.websockets import WebSocket

from radar_io.service.history import History

#: frames a client sends in one turn (one message per frame, or one array for batch clients)
QUANTUM = 16
#: frames all clients of one event loop send in one loop iteration, at most (~0.5-1 ms of
#: websocket sends on a 2-core x86; then HTTP requests get their turn)
ROUND_SENDS = 64
#: dispatches are at least this far apart per full-rate ``batch=1`` client beyond the
#: first :data:`UNSPACED_BATCH_CLIENTS` (s): such a client costs one frame per dispatch
#: (the others: one per message, or ``max_hz`` at most), so 200 of them get 48 ms blocks
#: (~4 000 frames/s, as the old 50 ms tick), 20 of them 3 ms blocks, a few every read
SPACING_PER_BATCH_CLIENT_S = 250e-6
UNSPACED_BATCH_CLIENTS = 8
#: a one-message-per-frame client whose oldest waiting message is older than this (s)
#: skips ahead to the newest block (it cannot keep up: fresh data beats a growing lag)
MAX_LAG_S = 2.0


class SendTurns:
    """Fair turns for the websocket senders of one event loop (see the module doc).

    :meth:`take` charges a turn of ``n`` frames against the current loop iteration's
    :data:`ROUND_SENDS`; when the round is spent (or others are already waiting) the
    caller waits in line and is charged in a later iteration. Nothing is held across a
    send, so a client blocked on a full socket holds up no one."""

    def __init__(self, loop: asyncio.AbstractEventLoop, round_sends: int = ROUND_SENDS) -> None:
        self.loop = loop
        self.round_sends = round_sends
        self.left = round_sends
        self.waiting: deque[tuple[asyncio.Future[None], int]] = deque()
        self._armed = False

    def take(self, n: int) -> asyncio.Future[None] | None:
        """A turn of ``n`` frames: None = send now; else a future to await first."""
        if not self._armed:  # a new round starts with the next loop iteration
            self._armed = True
            self.loop.call_soon(self._refill)
        if self.left > 0 and not self.waiting:
            self.left -= n
            return None
        fut = self.loop.create_future()
        self.waiting.append((fut, n))
        return fut

    def _refill(self) -> None:
        self._armed = False
        self.left = self.round_sends
        while self.waiting and self.left > 0:
            fut, n = self.waiting.popleft()
            if not fut.done():  # a client gone meanwhile is cancelled
                self.left -= n
                fut.set_result(None)
        if self.left < self.round_sends:  # the woken senders run in the next iteration
            self._armed = True
            self.loop.call_soon(self._refill)


_TURNS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, SendTurns] = \
    weakref.WeakKeyDictionary()


def turns_for(loop: asyncio.AbstractEventLoop) -> SendTurns:
    """The :class:`SendTurns` of ``loop`` (one per loop, shared by every hub on it)."""
    t = _TURNS.get(loop)
    if t is None:
        t = _TURNS[loop] = SendTurns(loop)
    return t


class Block:
    """Messages published together: shared, immutable, the array text built once."""

    __slots__ = ("_array", "first", "items", "last", "t_mono")

    def __init__(self, items: list[tuple[int, str]], t_mono: float = 0.0) -> None:
        self.items = items
        self.first, self.last = items[0][0], items[-1][0]
        self.t_mono = t_mono  #: dispatch time (monotonic s)
        self._array: str | None = None

    @property
    def array(self) -> str:
        """The block as one JSON array text (built on first use, then shared)."""
        if self._array is None:
            self._array = "[" + ",".join(t for _, t in self.items) + "]"
        return self._array


class Client:
    """One websocket client: its queue of blocks, its waiting state messages, its sender."""

    def __init__(self, ws: WebSocket, queue_size: int, max_hz: float | None,
                 batch: bool = False, turns: SendTurns | None = None) -> None:
        self.ws = ws
        self.queue: deque[Block] = deque()
        self.head = 0    #: messages of queue[0] already sent (one-message-per-frame clients)
        self.queued = 0  #: messages waiting
        self.events: dict[str, str] = {}  #: newest state message per kind, waiting
        self.queue_size = queue_size
        self.min_interval = 1.0 / max_hz if max_hz else 0.0
        self.batch = batch
        self.turns = turns
        self.dropped = 0
        self.sent = 0
        self.last_sent = 0
        self.wake = asyncio.Event()

    def push(self, block: Block) -> None:
        """Queue a block (event-loop thread); skip the oldest beyond ``queue_size`` messages,
        and all but this block when the client is :data:`MAX_LAG_S` behind."""
        q = self.queue
        if self.min_interval:  # decimated: only the newest matters
            q.clear()
            self.head = 0
            q.append(Block([block.items[-1]], block.t_mono))
            self.queued = 1
        else:
            behind = bool(q) and not self.batch and block.t_mono - q[0].t_mono > MAX_LAG_S
            q.append(block)
            self.queued += len(block.items)
            while len(q) > 1 and (behind or self.queued > self.queue_size):
                skipped = len(q.popleft().items) - self.head
                self.head = 0
                self.queued -= skipped
                self.dropped += skipped
        self.wake.set()

    def push_event(self, kind: str, text: str) -> None:
        """Queue a state message; it replaces one of the same kind still waiting."""
        self.events.pop(kind, None)  # re-inserted last: kinds go out in order of change
        self.events[kind] = text
        self.wake.set()

    async def _send_text(self, text: str) -> None:
        await self.ws.send({"type": "websocket.send", "text": text})

    async def _turn(self) -> None:
        """Wait for a turn, then send up to :data:`QUANTUM` frames: state messages first."""
        n = min(QUANTUM, len(self.events) + (1 if self.batch else self.queued)) or 1
        wait = self.turns.take(n) if self.turns is not None else None
        if wait is not None:
            await wait
        while self.events and n > 0:
            kind = next(iter(self.events))
            await self._send_text(self.events.pop(kind))
            n -= 1
        if n <= 0 or not self.queue:
            return
        if self.batch:
            blocks = list(self.queue)
            self.queue.clear()
            self.queued = 0
            await self._send_blocks(blocks)
            return
        q = self.queue
        while q and n > 0:
            b = q[0]
            seq, text = b.items[self.head]
            self.head += 1  # taken before the send: a push meanwhile sees a consistent queue
            self.queued -= 1
            if self.head == len(b.items):
                q.popleft()
                self.head = 0
            if seq <= self.last_sent:  # already sent by the backfill
                continue
            await self._send_text(text)
            self.last_sent = seq
            self.sent += 1
            n -= 1

    async def _send_items(self, items: list[tuple[int, str]]) -> None:
        """Messages outside the live queue (the backfill), in turns."""
        items = [it for it in items if it[0] > self.last_sent]
        if self.batch and items:
            await self._send_text("[" + ",".join(t for _, t in items) + "]")
            self.last_sent = items[-1][0]
            self.sent += len(items)
            return
        for k in range(0, len(items), QUANTUM):
            wait = self.turns.take(QUANTUM) if self.turns is not None else None
            if wait is not None:
                await wait
            for seq, text in items[k:k + QUANTUM]:
                await self._send_text(text)
                self.last_sent = seq
                self.sent += 1

    async def _send_blocks(self, blocks: list[Block]) -> None:
        """Batch client: every waiting block as one frame — a single block's shared array
        text, or the shared texts joined (the sends per second fall as load rises)."""
        blocks = [b for b in blocks if b.last > self.last_sent]
        if not blocks:
            return
        if blocks[0].first <= self.last_sent:  # overlaps the backfill: per message
            await self._send_items([it for b in blocks for it in b.items])
            return
        text = blocks[0].array if len(blocks) == 1 else \
            "[" + ",".join(b.array[1:-1] for b in blocks) + "]"
        await self._send_text(text)
        self.last_sent = blocks[-1].last
        self.sent += sum(len(b.items) for b in blocks)

    async def run(self, history: History, resume_after: int | None) -> None:
        """The client's sender: the backfill after ``resume_after``, then the live queue."""
        if resume_after is not None:
            after = resume_after
            while True:  # backfill in slices; live messages keep queuing meanwhile
                items = history.since(after, 2000)
                if not items:
                    break
                await self._send_items(items)
                after = items[-1][0]
        while True:
            if not (self.queue or self.events):
                self.wake.clear()
                await self.wake.wait()
                continue
            data = bool(self.queue)
            await self._turn()
            if self.min_interval and data:
                await asyncio.sleep(self.min_interval)
            elif self.queue or self.events:  # a send that does not block never yields:
                await asyncio.sleep(0)        # the others' turns come first


class Hub:
    """The set of live websocket clients of one message stream (the live service, or a
    replay session with its own history) and its dispatch."""

    def __init__(self, history: History, queue_size: int = 5000, max_clients: int = 500,
                 interval_s: float = 0.0) -> None:
        self.history = history
        self.queue_size = queue_size
        self.max_clients = max_clients
        self.interval_s = interval_s
        self.clients: set[Client] = set()
        self.loop: asyncio.AbstractEventLoop | None = None
        self.turns: SendTurns | None = None
        self.batch_clients = 0  #: full-rate batch=1 clients (they set the dispatch spacing)
        self.refused = 0
        self.undispatched = 0  #: messages dropped before dispatch (loop overloaded)
        self.max_pending = max(10 * queue_size, 20000)
        self.dispatches = 0  #: dispatches of messages so far
        self._dropped_closed = 0
        self._pending: list[tuple[int, str]] = []
        self._events: dict[str, str] = {}
        self._lock = threading.Lock()
        self._scheduled = False
        self.last_publish_mono = 0.0  #: monotonic time of the last dispatch of messages

    def attach(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.turns = turns_for(loop)

    def _schedule(self, loop: asyncio.AbstractEventLoop) -> None:
        """One dispatch on the loop: as soon as it is free, but not sooner after the last than
        ``interval_s`` or :data:`SPACING_PER_BATCH_CLIENT_S` per full-rate batch client
        beyond the first few."""
        try:
            beyond = max(0, self.batch_clients - UNSPACED_BATCH_CLIENTS)
            spacing = max(self.interval_s, beyond * SPACING_PER_BATCH_CLIENT_S)
            delay = self.last_publish_mono + spacing - time.monotonic()
            if delay > 0:
                loop.call_soon_threadsafe(loop.call_later, delay, self._dispatch)
            else:
                loop.call_soon_threadsafe(self._dispatch)
        except RuntimeError:  # loop closing at shutdown
            pass

    def publish_threadsafe(self, items: list[tuple[int, str]]) -> None:
        """From the reader thread: gather; one dispatch is pending at a time."""
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
        self._schedule(loop)

    def publish_event_threadsafe(self, text: str, kind: str = "alarm") -> None:
        """A state message outside the history (the alarm list), for every client; the
        newest of each ``kind`` replaces an older one not yet dispatched or sent. Any thread."""
        loop = self.loop
        if loop is None or loop.is_closed():
            return
        with self._lock:
            self._events[kind] = text
            if self._scheduled:
                return
            self._scheduled = True
        self._schedule(loop)

    def _dispatch(self) -> None:
        with self._lock:
            items, self._pending = self._pending, []
            events, self._events = self._events, {}
            self._scheduled = False
        for kind, text in events.items():
            for c in self.clients:
                c.push_event(kind, text)
        if not items:
            return
        self.dispatches += 1
        self.last_publish_mono = time.monotonic()
        block = Block(items, self.last_publish_mono)
        for c in self.clients:
            c.push(block)

    def full(self) -> bool:
        return len(self.clients) >= self.max_clients

    def register(self, ws: WebSocket, max_hz: float | None, batch: bool = False) -> Client:
        c = Client(ws, self.queue_size, max_hz, batch, self.turns)
        self.clients.add(c)
        self.batch_clients += batch and not max_hz
        return c

    def unregister(self, c: Client) -> None:
        if c in self.clients:
            self.clients.discard(c)
            self.batch_clients -= c.batch and not c.min_interval
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
