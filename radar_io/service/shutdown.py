"""A stop in bounded time (config ``shutdown_timeout_s``).

:class:`Shutdown` starts the steps that protect the data at once, on a thread of their own
(stop the reader, close and fsync the recording), while the server is still closing its
connections; :meth:`Shutdown.finish` then waits for them and runs the other steps one
after the other, each on a thread of its own, each waiting only for the time left of the
budget (at least :data:`MIN_STEP_S`). A step that overruns is logged and left behind (its
thread is a daemon): a hung uplink, broker or archive can never hold the process.
:class:`GracefulServer` is uvicorn's server starting those first steps as soon as it
begins to shut down, before it waits for its connections.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import uvicorn

log = logging.getLogger("radar_io.service")

#: every step gets at least this long (s), even once the budget is spent
MIN_STEP_S = 0.2

Step = tuple[str, Callable[[], object]]


def _run(steps: Sequence[Step]) -> None:
    for name, step in steps:
        t0 = time.monotonic()
        try:
            step()
        except Exception:  # the other steps must still run
            log.exception("stopping %s", name)
        else:
            log.info("stopped %s in %.2f s", name, time.monotonic() - t0)


class Shutdown:
    """One stop: ``first`` steps now, the rest in :meth:`finish`, all within ``budget_s``."""

    def __init__(self, budget_s: float, first: Sequence[Step]) -> None:
        self.budget_s = budget_s
        self.deadline = time.monotonic() + budget_s
        self._first = threading.Thread(target=_run, args=(list(first),), daemon=True,
                                       name="shutdown-first")
        self._first.start()
        self._finished = False

    def left_s(self) -> float:
        """Time left of the budget (s, monotonic), at least :data:`MIN_STEP_S`."""
        return max(self.deadline - time.monotonic(), MIN_STEP_S)

    def finish(self, steps: Sequence[Step]) -> None:
        """Wait for the first steps, then run ``steps`` in order, each bounded; once only."""
        if self._finished:
            return
        self._finished = True
        self._first.join(self.left_s())
        if self._first.is_alive():
            log.error("the first steps of the stop (reader, recording) still run after the "
                      "shutdown budget of %g s", self.budget_s)
        for name, step in steps:
            t = threading.Thread(target=_run, args=([(name, step)],), daemon=True,
                                 name=f"shutdown-{name}")
            t.start()
            t.join(self.left_s())
            if t.is_alive():
                log.error("stopping %s: still running after the shutdown budget of %g s; "
                          "left behind", name, self.budget_s)


class GracefulServer(uvicorn.Server):
    """uvicorn's server calling ``begin_shutdown()`` (the service's first stop steps) when
    it starts to shut down, before it waits for its connections to close."""

    def __init__(self, config: uvicorn.Config, begin_shutdown: Callable[[], None]) -> None:
        super().__init__(config)
        self._begin_shutdown = begin_shutdown

    async def shutdown(self, sockets: Any = None) -> None:
        self._begin_shutdown()
        await super().shutdown(sockets)
