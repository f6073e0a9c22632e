"""The live air-data reader on python-can's virtual bus: samples in SI units, and a bus that
fails (adapter pulled) is closed and reopened with back-off; samples flow again."""

from __future__ import annotations

import threading
import time
import uuid

import can
import pytest

from radar_io.errors import ConfigError
from radar_io.simulation.aircraft import AircraftSimulator
from radar_io.simulation.radar import FlightScript, SimConfig
from radar_io.sources.airdata import AirDataReader


def _until(cond, timeout_s: float = 15.0) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


def test_reader_reopens_a_failed_bus_and_samples_flow_again():
    channel = f"air-{uuid.uuid4().hex[:12]}"
    stop = threading.Event()

    def aircraft() -> None:
        bus = can.Bus(interface="virtual", channel=channel)
        sim = AircraftSimulator(FlightScript(), SimConfig(sync_every_s=2.0), duration_s=60.0)
        t0, t = time.monotonic(), 0.0
        while not stop.is_set() and t < 59.0:
            now = time.monotonic() - t0
            if now > t:
                sim.send(bus, t, now)
                t = now
            time.sleep(0.05)
        bus.shutdown()

    reader = AirDataReader("virtual", channel, lambda: None)
    ac = threading.Thread(target=aircraft, daemon=True)
    try:
        reader.start()
        ac.start()
        _until(lambda: reader.stats()["samples_received"] >= 3)
        st = reader.stats()
        assert st["connected"] and st["reconnects"] == 0 and st["last_error"] is None
        s = reader.since(0, 10)[-1]
        assert s["ias_mps"] is not None and 20 < s["ias_mps"] < 200  # knots → m/s
        reader.bus.shutdown()  # the adapter is pulled under the reader
        _until(lambda: reader.stats()["reconnects"] == 1 and reader.connected)
        assert reader.stats()["last_error"]
        n = reader.stats()["samples_received"]
        _until(lambda: reader.stats()["samples_received"] >= n + 3)
    finally:
        stop.set()
        reader.close()
        ac.join(5)


def test_unknown_interface_is_refused_in_one_line():
    with pytest.raises(ConfigError, match="can: unknown python-can interface 'nosuchcan'"):
        AirDataReader("nosuchcan", "x", lambda: None)
