"""Replay sessions: each a :class:`~radar_io.service.pipeline.Pipeline` of its own beside the
live one (as Yamcs runs replay processors beside the realtime processor).

A session reads a :class:`~radar_io.sources.replay.ReplaySource` on its own thread, through
its own framer and decoder (the live calibration, site and path deviation at creation),
into its own bounded history and websocket hub (``/ws/replays/{id}``). It is built with no
recorder, no sink, no alarm feed and no MQTT publisher, so nothing it decodes can reach a
live output, the recording or the sync-event index. Its messages carry the recorded
receive time ``t_ns`` of the chunk that completed the frame and ``"replay": <id>``.

At most ``max_replays`` sessions run (beyond: :class:`SessionLimit`, HTTP 429); a session
with no websocket client ends ``idle_s`` after its last client left or its last control
call (monotonic clock).
"""

from __future__ import annotations

import asyncio
import logging
import secrets
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from radar_io.errors import NotFoundError, RadarIOError
from radar_io.service.history import History
from radar_io.service.hub import Hub
from radar_io.service.pipeline import Pipeline, Processor, RecordedClock
from radar_io.sources.replay import ReplaySource

log = logging.getLogger("radar_io.sessions")

#: messages kept per session for ``from=`` resume (bytes of JSON text)
SESSION_HISTORY_BYTES = 16 << 20


class SessionLimit(RadarIOError):
    """``max_replays`` sessions run already (HTTP 429)."""


class ReplaySession:
    """One replay: its source, pipeline, history and hub."""

    def __init__(self, sid: str, recording: str, source: ReplaySource, pipeline: Pipeline,
                 hub: Hub) -> None:
        self.id, self.recording = sid, recording
        self.source, self.pipeline, self.hub = source, pipeline, hub
        self.history = pipeline.history
        self.touched_mono = time.monotonic()  #: last control call or last client seen
        #: the closing of the clients, held until done (the loop keeps only weak references)
        self._closing: set[asyncio.Future[None]] = set()

    @property
    def ws(self) -> str:
        return f"/ws/replays/{self.id}"

    def touch(self) -> None:
        self.touched_mono = time.monotonic()

    def idle_s(self, now: float) -> float:
        """Seconds nobody has watched it (0 while a websocket client is connected)."""
        if self.hub.clients:
            self.touched_mono = now
            return 0.0
        return now - self.touched_mono

    def state(self) -> dict[str, Any]:
        st = self.pipeline.status()
        return {"id": self.id, "ws": self.ws, **self.source.state(),
                "frames": st["frames"], "seq_gaps": st["seq_gaps"], "crc_errors": st["crc_errors"],
                "last_error": st["last_error"], "ws_clients": len(self.hub.clients),
                "last_msg_seq": self.history.last_seq}

    def brief(self) -> dict[str, Any]:
        """What ``/api/status`` lists per session."""
        s = self.source.state()
        return {"id": self.id, "recording": self.recording, "position_s": s["position_s"],
                "duration_s": s["duration_s"], "speed": s["speed"], "paused": s["paused"],
                "finished": s["finished"], "ws_clients": len(self.hub.clients)}

    def stop(self) -> None:
        """Stop the reader thread and close the session's websocket clients."""
        self.pipeline.stop()
        loop = self.hub.loop
        if loop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(self._close_clients)
            except RuntimeError:  # loop closing at shutdown
                pass

    def _close_clients(self) -> None:
        """On the event loop: close every client (its handler then unregisters it)."""
        for c in list(self.hub.clients):
            task = asyncio.ensure_future(_close_quietly(c.ws, f"replay session {self.id} ended"))
            self._closing.add(task)
            task.add_done_callback(self._closing.discard)


async def _close_quietly(ws: Any, reason: str) -> None:
    try:
        await ws.close(1001, reason)
    except (RuntimeError, OSError):  # already closing or gone
        pass


class ReplaySessions:
    """The running sessions; created and deleted by the ``/api/replays`` routes, all stopped
    by :meth:`close` (``ServiceState.stop``).

    ``pipeline_options()`` gives what a new session's pipeline is built with at that
    moment: ``spec``, ``site``, ``calibration`` (the live one) and ``processors`` (stateless
    extras such as the path deviation) — never the live outputs.
    """

    def __init__(self, pipeline_options: Callable[[], dict[str, Any]], *, max_sessions: int = 4,
                 idle_s: float = 300.0, ws_queue_size: int = 5000, ws_max_clients: int = 500,
                 ws_batch_interval_s: float = 0.05) -> None:
        self.pipeline_options = pipeline_options
        self.max_sessions, self.idle_s = max_sessions, idle_s
        self._hub_args = (ws_queue_size, ws_max_clients, ws_batch_interval_s)
        self._sessions: dict[str, ReplaySession] = {}
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop = threading.Event()
        self._reaper: threading.Thread | None = None
        self.ended_idle = 0  #: sessions ended because nobody watched them

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Attach the event loop (for the sessions' hubs) and start the idle reaper."""
        self._loop = loop
        self._reaper = threading.Thread(target=self._reap_loop, name="replay-reaper", daemon=True)
        self._reaper.start()

    def create(self, recording: str, path: Path, *, speed: float = 1.0, start_s: float = 0.0,
               size_bytes: int | None = None) -> ReplaySession:
        """A new running session replaying ``path`` (up to ``size_bytes`` when given) from
        ``start_s``. SessionLimit beyond ``max_sessions``; RecordingError for a bad file."""
        with self._lock:
            if len(self._sessions) >= self.max_sessions:
                raise SessionLimit(f"{self.max_sessions} replay sessions run already "
                                   "(max_replays): delete one first")
        source = ReplaySource(path, speed, size_bytes)  # a damaged file: RecordingError → 422
        if start_s > 0:
            source.seek(start_s)
        sid = secrets.token_hex(4)
        opts = self.pipeline_options()
        processors: list[Processor] = opts.pop("processors", [])
        history = History(SESSION_HISTORY_BYTES)
        hub = Hub(history, *self._hub_args)
        if self._loop is not None:
            hub.attach(self._loop)
        pipe = Pipeline(source, history=history, publish=hub.publish_threadsafe,
                        clock=RecordedClock(source), replay=sid, name=f"replay-{sid}", **opts)
        pipe.processors.extend(processors)
        session = ReplaySession(sid, recording, source, pipe, hub)
        with self._lock:
            if len(self._sessions) >= self.max_sessions:  # another request won the race
                raise SessionLimit(f"{self.max_sessions} replay sessions run already "
                                   "(max_replays): delete one first")
            self._sessions[sid] = session
        pipe.start()
        log.info("replay session %s: %s at x%g from %.3f s", sid, recording, speed, start_s)
        return session

    def get(self, sid: str) -> ReplaySession:
        with self._lock:
            s = self._sessions.get(sid)
        if s is None:
            raise NotFoundError(f"no replay session {sid!r}")
        return s

    def running(self) -> list[ReplaySession]:
        with self._lock:
            return list(self._sessions.values())

    def delete(self, sid: str) -> ReplaySession:
        with self._lock:
            s = self._sessions.pop(sid, None)
        if s is None:
            raise NotFoundError(f"no replay session {sid!r}")
        s.stop()
        return s

    def brief(self) -> list[dict[str, Any]]:
        return [s.brief() for s in self.running()]

    def reap(self, now: float | None = None) -> list[str]:
        """End the sessions nobody watched for ``idle_s``; their ids."""
        now = time.monotonic() if now is None else now
        ended = [s.id for s in self.running() if s.idle_s(now) >= self.idle_s]
        for sid in ended:
            try:
                self.delete(sid)
            except NotFoundError:  # deleted meanwhile
                continue
            self.ended_idle += 1
            log.info("replay session %s ended: nobody watched it for %.0f s", sid, self.idle_s)
        return ended

    def _reap_loop(self) -> None:
        period = min(1.0, self.idle_s / 4)
        while not self._stop.wait(period):
            try:
                self.reap()
            except Exception:  # the reaper must keep running
                log.exception("reaping replay sessions")

    def close(self) -> None:
        """Stop the reaper and every session."""
        self._stop.set()
        if self._reaper is not None:
            self._reaper.join(5)
        for s in self.running():
            try:
                self.delete(s.id)
            except NotFoundError:
                pass
