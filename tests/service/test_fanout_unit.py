"""The history bounded in bytes, the fan-out sharing one text per message and per block,
slow clients skipping ahead, and the pure bias pairing — without a server."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from radar_io.calibration.pairing import estimate_bias
from radar_io.errors import ValidationError
from radar_io.service.history import History
from radar_io.service.hub import Hub
from radar_io.service.pipeline import encode_message


def msgs(n: int, pad: int = 100) -> list[dict]:
    return [{"sr_m": float(i), "pad": "x" * pad} for i in range(n)]


def test_history_is_bounded_in_bytes_and_keeps_the_newest():
    h = History(max_bytes=50_000)
    out = []
    for _ in range(20):
        out += h.append(msgs(100), encode_message)
    assert h.nbytes <= 50_000 and h.nbytes == sum(len(t) for _, t in h.latest(len(h)))
    dropped_last = out[h.first_seq - 2][1]  # the newest message no longer held
    assert h.nbytes + len(dropped_last) > 50_000  # as many whole messages as fit
    assert h.last_seq == 2000 and h.latest(1)[0][0] == 2000
    assert [s for s, _ in h.since(h.first_seq - 1)] == list(range(h.first_seq, 2001))
    assert json.loads(h.latest(1)[0][1])["msg_seq"] == 2000
    assert h.latest_message["msg_seq"] == 2000


class FakeWS:
    """Records what a client is sent; ``gate`` holds a slow client's sends."""

    def __init__(self, gate: asyncio.Event | None = None) -> None:
        self.sent: list[str] = []
        self.gate = gate

    async def send(self, msg: dict) -> None:
        if self.gate is not None:
            await self.gate.wait()
        self.sent.append(msg["text"])


def test_one_text_per_message_and_per_block_shared_by_every_client():
    async def main() -> tuple[list[FakeWS], list[FakeWS], list]:
        h = History()
        hub = Hub(h, queue_size=10_000, interval_s=0.0)
        hub.attach(asyncio.get_running_loop())
        singles = [FakeWS() for _ in range(3)]
        batches = [FakeWS() for _ in range(3)]
        tasks = [asyncio.create_task(hub.register(ws, None, False).run(h, None)) for ws in singles]
        tasks += [asyncio.create_task(hub.register(ws, None, True).run(h, None)) for ws in batches]
        published = []
        for _ in range(5):
            items = h.append(msgs(10), encode_message)
            published += items
            hub.publish_threadsafe(items)
            await asyncio.sleep(0.01)
        for t in tasks:
            t.cancel()
        return singles, batches, published

    singles, batches, published = asyncio.run(main())
    for ws in singles:  # the very text objects the history encoded, no copy per client
        assert len(ws.sent) == 50 and all(a is b for a, (_, b) in zip(ws.sent, published, strict=True))
    for ws in batches:  # one array per block, the same object for every batch client
        assert len(ws.sent) == 5 and all(a is b for a, b in zip(ws.sent, batches[0].sent, strict=True))
        assert [m["msg_seq"] for arr in ws.sent for m in json.loads(arr)] == list(range(1, 51))


def test_a_slow_client_skips_ahead_and_never_holds_the_others():
    async def main() -> tuple[FakeWS, FakeWS, Hub]:
        h = History()
        hub = Hub(h, queue_size=100, interval_s=0.0)
        hub.attach(asyncio.get_running_loop())
        gate = asyncio.Event()
        slow, fast = FakeWS(gate), FakeWS()
        tasks = [asyncio.create_task(hub.register(ws, None, True).run(h, None))
                 for ws in (slow, fast)]
        for _ in range(50):
            hub.publish_threadsafe(h.append(msgs(10, 10), encode_message))
            await asyncio.sleep(0)
        await asyncio.sleep(0.01)
        gate.set()  # the slow client wakes up
        await asyncio.sleep(0.05)
        for t in tasks:
            t.cancel()
        return slow, fast, hub

    slow, fast, hub = asyncio.run(main())
    got_fast = [m["msg_seq"] for a in fast.sent for m in json.loads(a)]
    got_slow = [m["msg_seq"] for a in slow.sent for m in json.loads(a)]
    assert got_fast == list(range(1, 501))
    assert got_slow[-1] == 500 and len(got_slow) <= 110 + 10  # skipped to the newest
    gaps = np.flatnonzero(np.diff(got_slow) != 1)
    assert got_slow[:10] == list(range(1, 11))  # the block it was sending when it stalled
    assert len(gaps) == 1 and gaps[0] == 9  # then one skip ahead, then consecutive
    assert hub.dropped == 500 - len(got_slow)


EVENTS = {"r1": [
    {"complete": False, "rx_good": True, "seq": 1, "tod_s": 0.0, "sr_m": 1.0, "el_deg": 1.0,
     "az_deg": 1.0},
    {"complete": True, "rx_good": True, "seq": 1000, "tod_s": 1.0, "sr_m": 5000.0,
     "el_deg": 3.0, "az_deg": 45.0},
    {"complete": True, "rx_good": False, "seq": 2000, "tod_s": 2.0, "sr_m": 5100.0,
     "el_deg": 3.1, "az_deg": 46.0},
    {"complete": True, "rx_good": True, "seq": 3000, "tod_s": 3.0, "sr_m": 5200.0,
     "el_deg": 3.2, "az_deg": 359.99},
]}


def test_bias_pairing_is_photo_minus_radar_per_axis_with_azimuth_wrapped():
    obs = [{"group": "g", "recording": "r1", "sync_index": 1, "photo_sr_m": 5003.0,
            "photo_el_deg": 3.01, "photo_az_deg": 45.02},
           {"group": "g", "recording": "r1", "sync_index": 3, "photo_sr_m": 5203.0,
            "photo_el_deg": 3.21, "photo_az_deg": 0.01}]
    doc = estimate_bias(obs, EVENTS, "cal-1")
    comb = doc["statistics"]["combined"]
    assert comb["n"] == 2
    assert comb["dsr_m"]["mean"] == pytest.approx(3.0)
    assert comb["del_deg"]["mean"] == pytest.approx(0.01)
    assert comb["daz_deg"]["mean"] == pytest.approx(0.02)  # 0.01 − 359.99 wraps to +0.02
    assert [p["seq"] for p in doc["pairs"]] == [1000, 3000]
    assert doc["calibration"]["id"] == "cal-1"


@pytest.mark.parametrize("change,words", [
    ({"sync_index": 9}, "no index 9"), ({"sync_index": 0}, "began before"),
    ({"sync_index": 2}, "NG"), ({"photo_sr_m": None}, "give photo_x_m"),
    ({"recording": "r2"}, "0 sync events"),
])
def test_bias_pairing_refuses_unusable_observations_naming_them(change, words):
    ob = {"group": "g", "recording": "r1", "sync_index": 1, "photo_sr_m": 1.0,
          "photo_el_deg": 1.0, "photo_az_deg": 1.0, **change}
    with pytest.raises(ValidationError, match=words):
        estimate_bias([ob], EVENTS, "x")
