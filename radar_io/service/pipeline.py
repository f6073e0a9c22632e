"""One processing pipeline class, run once for the live radar and once per replay session.

A :class:`Pipeline` owns a reader thread and composes: a byte source (kept connected by
:class:`~radar_io.sources.reconnect.ReconnectingSource`), the framer, the decoder (with
the calibration), the site columns, the forward tracking filter (one per pipeline), extra
processors (path deviation), and publishers
(its own history's numbered messages go to its own hub). Only the live pipeline is given
the optional parts: the recorder (raw chunks first, GO-edge recording, the sync-event
index), and the live outputs as processors / publishers (sink fan-out, alarm feed, MQTT).
A replay session is another instance with none of those, so a replay cannot reach them
by construction.

Time stamps come from a clock: :class:`LiveClock` (now: wall-clock label and monotonic
receive time) or :class:`RecordedClock` (the recorded receive times of the chunk that the
replay source delivered last). A failed source is reported on the status and reopened
with back-off; nothing downstream (a slow browser) can block the reader thread.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from radar_io.coordinates.transforms import Site, geodetic, runway_xyh
from radar_io.decoding.biases import Calibration
from radar_io.decoding.frame_decoder import FrameDecoder
from radar_io.errors import RecordingError
from radar_io.framing.core import Framer
from radar_io.recording.recorder import Recorder, SyncEvent
from radar_io.service.history import History
from radar_io.sources import ByteSource, open_source, source_kind
from radar_io.sources.reconnect import ReconnectingSource
from radar_io.sources.replay import ReplaySource
from radar_io.wirespec.frame import FrameSpec

if TYPE_CHECKING:
    from radar_io.tracking.live import LiveTracker
    from radar_io.tracking.tracker import TrackParams

log = logging.getLogger("radar_io.pipeline")

Publish = Callable[[list[tuple[int, str]]], None]
Processor = Callable[[list[dict[str, Any]]], None]


def encode_message(m: dict[str, Any]) -> str:
    """JSON text of a message (NaN → null)."""
    return json.dumps(m, separators=(",", ":"), allow_nan=False)


class Clock(Protocol):
    def now(self) -> tuple[int, int]:
        """``(t_ns, mono_ns)`` of the chunk just read: wall-clock label, monotonic time."""


class LiveClock:
    """Receive time = now (wall clock as a label, monotonic clock for durations)."""

    def now(self) -> tuple[int, int]:
        return time.time_ns(), time.monotonic_ns()


class RecordedClock:
    """Receive time = the recorded ``t_ns`` / ``mono_ns`` of the chunk the replay source
    returned last (read on the reader thread right after that read)."""

    def __init__(self, source: ReplaySource) -> None:
        self.source = source

    def now(self) -> tuple[int, int]:
        return self.source.last_t_ns, self.source.last_mono_ns


class Pipeline:
    """Reader thread: source → [recorder] → framer → decoder → site columns → processors →
    history → publishers.

    ``source``: a URL or a :class:`ByteSource`; ``recorder``: the live recorder (None for a
    replay session: nothing recorded, no GO-edge recording, no sync index); ``clock``:
    where time stamps come from (default :class:`LiveClock`); ``replay``: put in every
    message as ``"replay"`` (a session id, ``True`` for ``serve --source replay://``);
    ``track``: the forward filter's :class:`~radar_io.tracking.tracker.TrackParams` (this
    pipeline gets a :class:`~radar_io.tracking.live.LiveTracker` of its own; its velocity
    fields go in every message before the processors run), None: no filter.
    """

    def __init__(self, source: str | ByteSource, spec: FrameSpec, history: History,
                 publish: Publish, *, recorder: Recorder | None = None,
                 site: Site | None = None, calibration: Calibration | None = None,
                 clock: Clock | None = None, replay: str | bool | None = None,
                 track: TrackParams | None = None, read_timeout_s: float = 0.05,
                 backoff_s: tuple[float, float] = (0.1, 5.0),
                 name: str = "radar-reader") -> None:
        self.spec, self.site, self.recorder, self.history = spec, site, recorder, history
        self.publishers: list[Publish] = [publish]
        self.processors: list[Processor] = []
        self.read_timeout_s = read_timeout_s
        self.clock: Clock = clock or LiveClock()
        self.replay = replay
        self.decoder = FrameDecoder(spec, calibration)
        self.framer = Framer(spec)
        self.tracker: LiveTracker | None = None
        if track is not None:
            from radar_io.tracking.live import LiveTracker

            self.tracker = LiveTracker(track)
        self.processing_errors = 0
        self.go = 0
        self.rx_good = 0
        self._last_sync = 0
        self._last_frame_mono: float | None = None
        self._rate: deque[tuple[float, int]] = deque()
        self._stop = threading.Event()
        src = open_source(source) if isinstance(source, str) else source
        self._link = ReconnectingSource(src, backoff_s, self._stop)
        self.kind = source_kind(src.url)
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    # -- control ---------------------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def set_calibration(self, cal: Calibration) -> None:
        self.decoder.calibration = cal  # read once per frame by the decoder: atomic swap

    @property
    def calibration(self) -> Calibration:
        return self.decoder.calibration

    @property
    def source(self) -> ByteSource:
        return self._link.source

    def status(self) -> dict[str, Any]:
        st = self.framer.stats
        now = time.monotonic()
        age = None if self._last_frame_mono is None else now - self._last_frame_mono
        rec = self.recorder
        return {
            "source": self._link.url, "source_kind": self.kind,
            "mode": "replay" if self.replay is not None else "live",
            "connected": self.connected,
            "frames": st.frames, "crc_errors": st.crc_errors, "implausible": st.implausible,
            "bytes_discarded": st.bytes_discarded, "seq_gaps": st.seq_gaps,
            "rate_hz": self.rate_hz(now), "go": self.go, "rx_good": self.rx_good,
            "last_frame_age_s": age, "reconnects": self.reconnects, "last_error": self.last_error,
            "recording_error": rec.last_error if rec is not None else None,
            "processing_errors": self.processing_errors,
        }

    def rate_hz(self, now: float | None = None) -> float:
        """Frames per second over the last 2 s (0 when nothing came for 1 s). Any thread."""
        now = time.monotonic() if now is None else now
        r = [e for e in list(self._rate) if now - e[0] <= 2.0]  # a snapshot: no shared mutation
        if len(r) < 2 or now - r[-1][0] >= 1.0:
            return 0.0
        span = r[-1][0] - r[0][0]
        return (sum(k for _, k in r) - r[0][1]) / span if span > 0.2 else 0.0

    @property
    def connected(self) -> bool:
        return self._link.connected

    @property
    def reconnects(self) -> int:
        return self._link.reconnects

    @property
    def last_error(self) -> str | None:
        return self._link.last_error

    # -- the reader thread -----------------------------------------------------------------
    def _run(self) -> None:
        """Read and process; any failure of the source is a disconnect with back-off
        (:class:`~radar_io.sources.reconnect.ReconnectingSource`). Never exits on error."""
        link = self._link
        while not self._stop.is_set():
            data = link.read(self.read_timeout_s)
            if not data:
                continue
            if getattr(link.source, "discontinuous", False):
                self._resync()  # replay seek: these bytes do not follow the previous ones
            t_ns, mono_ns = self.clock.now()
            try:
                self._process(data, t_ns, mono_ns)
            except Exception:  # a bug downstream must not stop acquisition
                self.processing_errors += 1
                log.exception("processing a chunk failed")
        link.close()

    def _resync(self) -> None:
        """The stream jumped (replay seek): drop the framer's partial frame and SEQ memory
        (counters kept) and count no sync edge on the first frame after the jump."""
        self.framer.flush()  # the partial frame before the jump: counted as discarded
        stats = self.framer.stats
        self.framer = Framer(self.spec)
        self.framer.stats = stats
        self._last_sync = 1
        if self.tracker is not None:
            self.tracker.reset()  # the track does not continue across the jump

    def _process(self, data: bytes, t_ns: int, mono_ns: int | None = None) -> None:
        rec = self.recorder
        if rec is not None:
            try:
                rec.on_chunk(data, t_ns, mono_ns)  # raw first: nothing received is lost
            except RecordingError as exc:  # reported on the status; decoding goes on
                log.error("recording failed: %s", exc)
        frames = self.framer.feed(data)
        if not frames:
            return
        decode = self.decoder.decode
        msgs = []
        sync_edges: list[tuple[dict[str, Any], str | None]] = []
        for fr in frames:
            m = decode(fr)
            m["t_ns"] = t_ns
            sync_edge = bool(m["sync"] and not self._last_sync)
            self._last_sync = m["sync"]
            if rec is not None and sync_edge and m["go"] < self.go:
                sync_edges.append((m, rec.current))  # GO falls on this frame: it ends the recording
                sync_edge = False
            if m["go"] != self.go:
                self.go = m["go"]
                if rec is not None:
                    rec.on_go_edge(bool(self.go))
            if rec is not None and sync_edge:
                sync_edges.append((m, rec.current))
            msgs.append(m)
        if self.replay is not None:
            for m in msgs:
                m["replay"] = self.replay
        self.rx_good = msgs[-1]["rx_good"]
        if self.site is not None:
            self._add_site_columns(msgs)
        if self.tracker is not None:
            try:
                self.tracker(msgs)
            except Exception:  # a bug here must not stop acquisition: no velocity, that is all
                self.processing_errors += 1
                log.exception("tracking filter failed")
        for proc in self.processors:
            try:
                proc(msgs)
            except Exception:  # one failing extra must not stop the others
                self.processing_errors += 1
                log.exception("processor %r failed", proc)
        now = time.monotonic()
        self._last_frame_mono = now
        r = self._rate  # mutated by this thread only
        r.append((now, len(msgs)))
        while now - r[0][0] > 2.0:
            r.popleft()
        numbered = self.history.append(msgs, encode_message)
        if rec is not None:
            for m, rec_id in sync_edges:
                rec.on_sync(SyncEvent(seq=m["seq"], tod_s=m["tod_s"], t_ns=t_ns,
                                      msg_seq=m["msg_seq"], recording=rec_id))
        for publish in self.publishers:
            publish(numbered)

    def _add_site_columns(self, msgs: list[dict[str, Any]]) -> None:
        good = [m for m in msgs if m["rx_good"]]
        for m in msgs:
            if not m["rx_good"]:
                m.update(xr_m=None, yr_m=None, hr_m=None, lat_deg=None, lon_deg=None, hae_m=None)
        if not good:
            return
        sr = np.array([m["sr_c_m"] for m in good])
        el = np.array([m["el_c_deg"] for m in good])
        az = np.array([m["az_c_deg"] for m in good])
        xr, yr, hr = runway_xyh(sr, el, az, self.site)  # type: ignore[arg-type]
        lat, lon, hae = geodetic(sr, el, az, self.site)  # type: ignore[arg-type]
        for i, m in enumerate(good):
            m.update(xr_m=float(xr[i]), yr_m=float(yr[i]), hr_m=float(hr[i]),
                     lat_deg=float(lat[i]), lon_deg=float(lon[i]), hae_m=float(hae[i]))
