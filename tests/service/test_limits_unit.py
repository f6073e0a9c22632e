"""The expensive-request limiter on its own: slots per kind, 429 with Retry-After, the work
in a worker process, and a fresh pool after a worker died."""

from __future__ import annotations

import asyncio
import operator
import os

import pytest
from fastapi import HTTPException

from radar_io.errors import UnavailableError
from radar_io.service.limits import ExpensiveLimiter


def test_slots_429_and_a_dead_worker():
    lim = ExpensiveLimiter({"sync": 1, "downloads": 1})

    async def main() -> None:
        assert await lim.run("sync", os.getpid) != os.getpid()  # in a worker process
        release = lim.acquire("downloads")
        with pytest.raises(HTTPException) as e:
            lim.acquire("downloads")
        assert e.value.status_code == 429 and int(e.value.headers["Retry-After"]) >= 1
        release()
        release()  # idempotent
        lim.acquire("downloads")()
        with pytest.raises(UnavailableError, match="died"):
            await lim.run("sync", os._exit, 3)
        assert await lim.run("sync", operator.add, 2, 3) == 5  # a new pool
        assert lim.stats()["sync"] == {"running": 0, "limit": 1, "refused": 0}
        assert lim.stats()["downloads"]["refused"] == 1

    try:
        asyncio.run(main())
    finally:
        lim.close()
