"""In-memory history of live measurement messages, numbered by a service-wide ``msg_seq``."""

from __future__ import annotations

import threading
from collections import deque
from typing import Any


class History:
    """A bounded, thread-safe ring of messages; ``msg_seq`` increases by one per message."""

    def __init__(self, maxlen: int = 120_000) -> None:
        self._items: deque[tuple[int, dict[str, Any], str]] = deque(maxlen=maxlen)
        self._lock = threading.Lock()
        self._next = 1

    def append(self, msgs: list[dict[str, Any]], encode: Any) -> list[tuple[int, str]]:
        """Number and store messages; returns ``(msg_seq, json_text)`` pairs."""
        out = []
        with self._lock:
            for m in msgs:
                seq = self._next
                self._next += 1
                m["msg_seq"] = seq
                text = encode(m)
                self._items.append((seq, m, text))
                out.append((seq, text))
        return out

    @property
    def last_seq(self) -> int:
        return self._next - 1

    @property
    def first_seq(self) -> int:
        with self._lock:
            return self._items[0][0] if self._items else self._next

    def since(self, after: int, limit: int | None = None) -> list[tuple[int, dict[str, Any], str]]:
        """Messages with ``msg_seq > after``, oldest first, at most ``limit``."""
        with self._lock:
            if not self._items:
                return []
            first = self._items[0][0]
            start = max(0, after + 1 - first)
            n = len(self._items)
            stop = n if limit is None else min(n, start + limit)
            return [self._items[i] for i in range(start, stop)]

    def latest(self, n: int) -> list[tuple[int, dict[str, Any], str]]:
        with self._lock:
            k = len(self._items)
            return [self._items[i] for i in range(max(0, k - n), k)]
