"""In-memory history of live measurement messages, numbered by a service-wide ``msg_seq``.

Messages are kept as their JSON text only (encoded once, shared by /api/track, the
websocket resume and every live client), and the ring is bounded in bytes
(``history_mb``), not in messages: the oldest texts go once the total exceeds it.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import Any

Encode = Callable[[dict[str, Any]], str]


class History:
    """A byte-bounded, thread-safe ring of ``(msg_seq, json_text)``; msg_seq +1 per message."""

    def __init__(self, max_bytes: int = 64 << 20) -> None:
        self.max_bytes = int(max_bytes)
        self._items: deque[tuple[int, str]] = deque()
        self._bytes = 0
        self._lock = threading.Lock()
        self._next = 1
        self.latest_message: dict[str, Any] | None = None  #: the newest message (dict)

    def append(self, msgs: list[dict[str, Any]], encode: Encode) -> list[tuple[int, str]]:
        """Number, encode once and store messages; returns ``(msg_seq, json_text)`` pairs."""
        if not msgs:
            return []
        out = []
        with self._lock:
            for m in msgs:
                m["msg_seq"] = self._next
                self._next += 1
                out.append((m["msg_seq"], encode(m)))
            self._items.extend(out)
            self._bytes += sum(len(t) for _, t in out)
            items = self._items
            while self._bytes > self.max_bytes and len(items) > 1:
                self._bytes -= len(items.popleft()[1])
            self.latest_message = msgs[-1]
        return out

    @property
    def nbytes(self) -> int:
        """Characters of JSON held (≈ bytes: the texts are ASCII)."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._items)

    @property
    def last_seq(self) -> int:
        return self._next - 1

    @property
    def first_seq(self) -> int:
        with self._lock:
            return self._items[0][0] if self._items else self._next

    def since(self, after: int, limit: int | None = None) -> list[tuple[int, str]]:
        """Messages with ``msg_seq > after``, oldest first, at most ``limit``."""
        with self._lock:
            if not self._items:
                return []
            first = self._items[0][0]
            start = max(0, after + 1 - first)
            n = len(self._items)
            stop = n if limit is None else min(n, start + limit)
            items = self._items
            return [items[i] for i in range(start, stop)]

    def latest(self, n: int) -> list[tuple[int, str]]:
        with self._lock:
            k = len(self._items)
            items = self._items
            return [items[i] for i in range(max(0, k - n), k)]
