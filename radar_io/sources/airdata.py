"""The aircraft's air data as a live source (radar-interface.md §9).

:class:`AirDataReader` reads the aircraft's 8 Hz air data from a CAN bus (python-can +
the DBC, :mod:`radar_io.sources.canbus`) on its own thread and keeps the recent samples
in SI units, with the radar ground range and height seen when each arrived (for the
profile overlay). Construct it (opens the bus), then :meth:`~AirDataReader.start`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from typing import Any

import numpy as np

log = logging.getLogger("radar_io.airdata")

KT = 1852.0 / 3600.0   # m/s per knot
FT = 0.3048            # m per foot
NM = 1852.0            # m per nautical mile


class AirDataReader:
    """The aircraft's 8 Hz air data from a CAN bus, kept for the API in SI units."""

    def __init__(self, interface: str, channel: str, latest_radar: Any,
                 bitrate: int | None = None, keep: int = 8 * 600) -> None:
        import can

        from radar_io.decoding.airdata import AirDataDecoder, load_dbc
        from radar_io.errors import ConfigError

        if interface not in can.interfaces.VALID_INTERFACES:
            raise ConfigError(f"can: unknown python-can interface {interface!r} (known: "
                              f"{', '.join(sorted(can.interfaces.VALID_INTERFACES))})")
        self.url = f"{interface}:{channel}"
        self._open_args = (interface, channel, bitrate)
        self.bus: Any = None           # opened (and reopened) by the reader thread
        self.connected = False
        self.reconnects = 0
        self.last_error: str | None = None
        self.decoder = AirDataDecoder(load_dbc())
        self.latest_radar = latest_radar  # () -> the newest radar message or None
        self.samples: deque[dict[str, Any]] = deque(maxlen=keep)
        self.shutter_events = 0
        self._seq = 0
        self._last_mono: float | None = None  # monotonic time of the last sample (its age)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-airdata", daemon=True)

    def start(self) -> None:
        """Start the reader thread (the service does it in its lifespan)."""
        if not self._thread.is_alive():
            self._thread.start()

    def _drop_bus(self, exc: Exception) -> None:
        """The bus failed (adapter pulled, interface down): close it; the loop reopens it."""
        msg = str(exc)
        if msg != self.last_error:  # one log line per distinct error
            log.warning("CAN %s: %s", self.url, msg)
        self.last_error, self.connected = msg, False
        bus, self.bus = self.bus, None
        if bus is not None:
            try:
                bus.shutdown()
            except Exception:  # noqa: BLE001 - it is gone anyway
                pass

    def _run(self) -> None:
        from radar_io.sources.canbus import open_bus

        pending: dict[str, float] | None = None
        backoff, opened_before = 0.1, False
        while not self._stop.is_set():
            if self.bus is None:
                try:
                    self.bus = open_bus(*self._open_args)
                except Exception as exc:  # noqa: BLE001 - absent adapter: retry with back-off
                    self._drop_bus(exc)
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, 5.0)
                    continue
                self.reconnects += opened_before
                opened_before, self.connected, backoff = True, True, 0.1
            try:
                m = self.bus.recv(0.2)
            except Exception as exc:  # noqa: BLE001 - reopen with back-off
                self._drop_bus(exc)
                continue
            if m is None:
                continue
            got = self.decoder.feed(m)
            if got is None:
                continue
            kind, row = got
            if kind == "event":
                self.shutter_events += 1
            elif kind == "sample_start":
                if pending is not None:
                    self._publish(pending)
                pending = row
            if pending is not None and all(k in pending for k in ("ias_kt", "pressure_altitude_ft",
                                                                   "pitch_deg", "dme2_nm")):
                self._publish(pending)
                pending = None

    def _publish(self, row: dict[str, float]) -> None:
        radar = self.latest_radar()
        g = h = None
        if radar is not None and radar.get("x_m") is not None:
            g = float(np.hypot(radar["x_m"], radar["y_m"]))
            h = radar["h_m"]

        def si(key: str, k: float) -> float | None:
            v = row.get(key)
            return None if v is None or v != v else v * k

        with self._lock:
            self._seq += 1
            self._last_mono = time.monotonic()
            self.samples.append({
                "air_seq": self._seq, "t_ns": time.time_ns(),  # a label
                "aircraft_time_s": row.get("time_s"), "ias_mps": si("ias_kt", KT),
                "pressure_altitude_m": si("pressure_altitude_ft", FT),
                "pitch_deg": row.get("pitch_deg"), "roll_deg": row.get("roll_deg"),
                "heading_deg": row.get("heading_deg"), "dme1_m": si("dme1_nm", NM),
                "dme2_m": si("dme2_nm", NM), "shutter_count": row.get("shutter_count"),
                "radar_ground_range_m": g, "radar_h_m": h,
            })

    def since(self, after: int, limit: int) -> list[dict[str, Any]]:
        with self._lock:
            return [s for s in self.samples if s["air_seq"] > after][:limit]

    def stats(self) -> dict[str, Any]:
        d = self.decoder
        return {"source": self.url, "connected": self.connected, "reconnects": self.reconnects,
                "last_error": self.last_error, "samples_received": self._seq,
                "shutter_events": self.shutter_events,
                "messages": d.messages, "unknown": d.unknown, "undecodable": d.undecodable,
                "last_sample_age_s": time.monotonic() - self._last_mono
                if self._last_mono is not None else None}

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2)
        bus, self.bus = self.bus, None
        if bus is not None:
            try:
                bus.shutdown()
            except Exception:  # noqa: BLE001
                pass
