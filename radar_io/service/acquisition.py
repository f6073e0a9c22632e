"""The acquisition pipeline: one reader thread owns the source.

Per read: record the raw chunk (before anything else), frame, decode, compensate,
add coordinates, number the messages into the history, hand them to the hub.
A failed source is reported on the status and reopened with back-off; nothing
downstream (a slow browser) can block this thread.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from ..calibration_set import Calibration
from ..decoding import FrameDecoder
from ..errors import RadarIOError, SourceError
from ..framing import Framer
from ..geometry import Site, geodetic, runway_xyh
from ..sources import ByteSource, open_source
from ..spec import FrameSpec
from .history import History
from .recorder import Recorder, SyncEvent

log = logging.getLogger("radar_io.acquisition")

Publish = Callable[[list[tuple[int, str]]], None]
Processor = Callable[[list[dict[str, Any]]], None]


def encode_message(m: dict[str, Any]) -> str:
    """JSON text of a message (NaN → null)."""
    return json.dumps(m, separators=(",", ":"), allow_nan=False)


class Acquisition:
    """Reader thread: source → recorder → framer → decoder → coordinates → history → publish."""

    def __init__(self, source_url: str, spec: FrameSpec, recorder: Recorder, history: History,
                 publish: Publish, *, site: Site | None = None,
                 calibration: Calibration | None = None, read_timeout_s: float = 0.05,
                 backoff_s: tuple[float, float] = (0.1, 5.0)) -> None:
        self.spec, self.site, self.recorder, self.history = spec, site, recorder, history
        self.publish = publish
        self.read_timeout_s = read_timeout_s
        self.backoff_s = backoff_s
        self.processors: list[Processor] = []
        self.live_url = source_url
        self._source: ByteSource = open_source(source_url)
        self._pending_source: ByteSource | None = None
        self.decoder = FrameDecoder(spec, calibration)
        self.framer = Framer(spec)
        self.connected = False
        self.reconnects = 0
        self.last_error: str | None = None
        self.go = 0
        self.rx_good = 0
        self._last_sync = 0
        self._last_frame_mono: float | None = None
        self._rate: deque[tuple[float, int]] = deque()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="radar-reader", daemon=True)
        self.mode = "live"

    # -- control ---------------------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        self._thread.join(timeout_s)

    def set_calibration(self, cal: Calibration) -> None:
        self.decoder.calibration = cal  # read once per frame by the decoder: atomic swap

    @property
    def calibration(self) -> Calibration:
        return self.decoder.calibration

    def switch_source(self, source: ByteSource, mode: str) -> None:
        """Hand the reader a new source (replay or back to live); done by the reader thread."""
        self._pending_source = source
        self._pending_mode = mode

    @property
    def source(self) -> ByteSource:
        return self._source

    def status(self) -> dict[str, Any]:
        st = self.framer.stats
        now = time.monotonic()
        age = None if self._last_frame_mono is None else now - self._last_frame_mono
        return {
            "source": self._source.url, "mode": self.mode, "connected": self.connected,
            "frames": st.frames, "crc_errors": st.crc_errors, "implausible": st.implausible,
            "bytes_discarded": st.bytes_discarded, "seq_gaps": st.seq_gaps,
            "rate_hz": self.rate_hz(now), "go": self.go, "rx_good": self.rx_good,
            "last_frame_age_s": age, "reconnects": self.reconnects, "last_error": self.last_error,
        }

    def rate_hz(self, now: float | None = None) -> float:
        now = time.monotonic() if now is None else now
        r = self._rate
        while r and now - r[0][0] > 2.0:
            r.popleft()
        if not r or now - r[0][0] <= 0:
            return 0.0
        n = sum(k for _, k in r) - r[0][1]
        span = r[-1][0] - r[0][0]
        return n / span if span > 0.2 and now - r[-1][0] < 1.0 else 0.0

    # -- the reader thread -----------------------------------------------------------------
    def _run(self) -> None:
        delay = self.backoff_s[0]
        while not self._stop.is_set():
            if self._pending_source is not None:
                self._swap_source()
            if not self.connected:
                try:
                    self._source.open()
                except RadarIOError as exc:
                    self._disconnected(str(exc))
                    self._stop.wait(delay)
                    delay = min(delay * 2, self.backoff_s[1])
                    continue
                self.connected = True
                self.last_error = None
                delay = self.backoff_s[0]
                log.info("source %s open", self._source.url)
            try:
                data = self._source.read(self.read_timeout_s)
            except SourceError as exc:
                self._source.close()
                self.reconnects += 1
                self._disconnected(str(exc))
                continue
            if data:
                try:
                    self._process(data, time.time_ns())
                except Exception:  # noqa: BLE001 - a bug downstream must not stop acquisition
                    log.exception("processing a chunk failed")
        self._source.close()
        self.connected = False

    def _disconnected(self, why: str) -> None:
        if self.connected or self.last_error != why:
            log.warning("source %s: %s", self._source.url, why)
        self.connected = False
        self.last_error = why

    def _swap_source(self) -> None:
        new, self._pending_source = self._pending_source, None
        self._source.close()
        self.connected = False
        self._source = new  # type: ignore[assignment]
        self.mode = self._pending_mode
        self.recorder.enabled = self.mode == "live"
        self.framer = Framer(self.spec)
        self._last_frame_mono = None
        self._rate.clear()

    def _process(self, data: bytes, t_ns: int) -> None:
        self.recorder.on_chunk(data, t_ns)  # raw first: nothing received is lost
        frames = self.framer.feed(data)
        if not frames:
            return
        decode = self.decoder.decode
        msgs = []
        sync_edges = []
        for fr in frames:
            m = decode(fr)
            m["t_ns"] = t_ns
            if m["go"] != self.go:
                self.go = m["go"]
                self.recorder.on_go_edge(bool(self.go))
            if m["sync"] and not self._last_sync:
                sync_edges.append(m)
            self._last_sync = m["sync"]
            msgs.append(m)
        self.rx_good = msgs[-1]["rx_good"]
        if self.site is not None:
            self._add_site_columns(msgs)
        for proc in self.processors:
            proc(msgs)
        now = time.monotonic()
        self._last_frame_mono = now
        self._rate.append((now, len(msgs)))
        numbered = self.history.append(msgs, encode_message)
        for m in sync_edges:
            self.recorder.on_sync(SyncEvent(seq=m["seq"], tod_s=m["tod_s"], t_ns=t_ns,
                                            msg_seq=m["msg_seq"], recording=None))
        self.publish(numbered)

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

