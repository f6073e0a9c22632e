"""``sim://``: the built-in radar simulator as a real-time byte source."""

from __future__ import annotations

import time
from dataclasses import fields

from radar_io.errors import SourceError
from radar_io.sources.base import parse_query, typed_params


class SimSource:
    """The radar simulator paced in real time; loops the flight forever.

    ``sim://?rate_hz=1000&seed=1&flip_rate=0&…``: any field of
    :class:`~radar_io.simulation.radar.SimConfig` or
    :class:`~radar_io.simulation.radar.FlightScript`.
    """

    def __init__(self, url: str = "sim://") -> None:
        from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

        self.url = url
        _, q = parse_query(url)
        script_keys = {f.name for f in fields(FlightScript)}
        sq = {k: v for k, v in q.items() if k in script_keys}
        cq = {k: v for k, v in q.items() if k not in script_keys}
        cfg = SimConfig(loop=True, **typed_params(SimConfig, cq, url))
        self.sim = RadarSimulator(FlightScript(**typed_params(FlightScript, sq, url)), cfg)
        self._t0: float | None = None
        self._sent = 0

    def open(self) -> None:
        self._t0 = time.monotonic()
        self._sent = 0

    def read(self, timeout_s: float) -> bytes:
        if self._t0 is None:
            raise SourceError("sim source is not open")
        rate = self.sim.cfg.rate_hz
        due = int((time.monotonic() - self._t0) * rate) - self._sent
        if due <= 0:
            wait = min(timeout_s, (self._sent + 1) / rate - (time.monotonic() - self._t0))
            if wait > 0:
                time.sleep(wait)
            due = int((time.monotonic() - self._t0) * rate) - self._sent
            if due <= 0:
                return b""
        due = min(due, int(rate))  # never more than a second's worth at once
        data, _ = self.sim.generate(due)
        self._sent += due
        return self.sim.corrupt(data)

    def close(self) -> None:
        self._t0 = None
