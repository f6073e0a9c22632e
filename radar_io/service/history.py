"""In-memory history of live measurement messages, numbered by a service-wide ``msg_seq``.

Messages are kept as their JSON text only (encoded once, shared by /api/track, the
websocket resume and every live client), and the ring is bounded in bytes
(``history_mb``), not in messages: the oldest texts go once the total exceeds it.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from itertools import islice
from typing import Any

Encode = Callable[[dict[str, Any]], str]
Item = tuple[int, str]

#: messages per block: a lookup walks the blocks (≈ 100 for 64 MiB), never the messages
BLOCK = 1024


class History:
    """A byte-bounded, thread-safe ring of ``(msg_seq, json_text)``; msg_seq +1 per message.

    The messages sit in blocks of :data:`BLOCK` (lists filled in order; only the last one
    grows). Since msg_seq is contiguous, a message is found by arithmetic, and a reader
    takes, under the lock, only the bounds and references to the blocks it needs; it
    copies the messages after releasing it, so the reader thread's ``append`` never waits
    for a large ``/api/track`` or websocket backfill. The oldest messages are dropped by
    advancing ``first_seq`` (a block goes once all its messages are dropped), which
    leaves the blocks a reader holds intact.
    """

    def __init__(self, max_bytes: int = 64 << 20) -> None:
        self.max_bytes = int(max_bytes)
        self._blocks: deque[list[Item]] = deque()
        self._first = 1  # msg_seq of the oldest message kept
        self._block0 = 1  # msg_seq of the first entry of _blocks[0]
        self._bytes = 0
        self._lock = threading.Lock()
        self._next = 1
        self.latest_message: dict[str, Any] | None = None  #: the newest message (dict)

    def append(self, msgs: list[dict[str, Any]], encode: Encode) -> list[Item]:
        """Number, encode once and store messages; returns ``(msg_seq, json_text)`` pairs."""
        if not msgs:
            return []
        out = []
        with self._lock:
            for m in msgs:
                m["msg_seq"] = self._next
                self._next += 1
                out.append((m["msg_seq"], encode(m)))
            blocks = self._blocks
            for item in out:
                if not blocks or len(blocks[-1]) == BLOCK:
                    blocks.append([])
                blocks[-1].append(item)
            self._bytes += sum(len(t) for _, t in out)
            while self._bytes > self.max_bytes and self._next - self._first > 1:
                k = self._first - self._block0
                self._bytes -= len(blocks[0][k][1])
                self._first += 1
                if k + 1 == BLOCK:  # every message of the oldest block dropped
                    blocks.popleft()
                    self._block0 += BLOCK
            self.latest_message = msgs[-1]
        return out

    @property
    def nbytes(self) -> int:
        """Characters of JSON held (≈ bytes: the texts are ASCII)."""
        return self._bytes

    def __len__(self) -> int:
        return self._next - self._first

    @property
    def last_seq(self) -> int:
        return self._next - 1

    @property
    def first_seq(self) -> int:
        return self._first  # == _next when empty

    def since(self, after: int, limit: int | None = None) -> list[Item]:
        """Messages with ``msg_seq > after``, oldest first, at most ``limit``."""
        with self._lock:  # bounds and block references only: O(number of blocks)
            lo = max(after + 1, self._first)
            hi = self._next if limit is None else min(self._next, lo + max(0, limit))
            if hi <= lo:
                return []
            b0, b1 = (lo - self._block0) // BLOCK, (hi - 1 - self._block0) // BLOCK
            blocks = list(islice(self._blocks, b0, b1 + 1))
            base = self._block0 + b0 * BLOCK
        out: list[Item] = []  # the copy, outside the lock (the blocks only ever grow)
        for j, block in enumerate(blocks):
            start = base + j * BLOCK
            out.extend(block[max(lo - start, 0):min(hi - start, BLOCK)])
        return out

    def latest(self, n: int) -> list[Item]:
        """The newest ``n`` messages, oldest first."""
        return self.since(self._next - 1 - n, n)
