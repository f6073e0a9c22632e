"""The live air-data reader on python-can's virtual bus: samples in SI units, and a bus that
fails (adapter pulled) is closed and reopened with back-off; samples flow again."""

from __future__ import annotations

import threading
import time
import uuid

import pytest
from conftest import fly_on_virtual_bus

from radar_io.errors import ConfigError
from radar_io.sources.airdata import AirDataReader


def _until(cond, timeout_s: float = 15.0) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


@pytest.mark.slow
def test_reader_reopens_a_failed_bus_and_samples_flow_again():
    channel = f"air-{uuid.uuid4().hex[:12]}"
    stop = threading.Event()
    reader = AirDataReader("virtual", channel, lambda: None)
    ac = threading.Thread(target=fly_on_virtual_bus, args=(channel, stop), daemon=True)
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
