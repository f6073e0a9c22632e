"""The history bounded in bytes, the fan-out sharing one text per message and per block,
slow clients skipping ahead, and the pure bias pairing — without a server."""

from __future__ import annotations

import asyncio
import json
import time

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


def test_a_per_message_client_too_far_behind_skips_ahead_to_the_newest(monkeypatch):
    monkeypatch.setattr("radar_io.service.hub.MAX_LAG_S", 0.05)

    async def main() -> tuple[FakeWS, Hub]:
        h = History()
        hub = Hub(h, queue_size=10_000, interval_s=0.0)
        hub.attach(asyncio.get_running_loop())
        gate = asyncio.Event()
        ws = FakeWS(gate)
        task = asyncio.create_task(hub.register(ws, None, False).run(h, None))
        for _ in range(3):  # 30 messages within 50 ms: kept
            hub.publish_threadsafe(h.append(msgs(10, 10), encode_message))
            await asyncio.sleep(0.005)
        await asyncio.sleep(0.06)
        hub.publish_threadsafe(h.append(msgs(10, 10), encode_message))  # 60 ms later
        await asyncio.sleep(0.01)
        gate.set()
        await asyncio.sleep(0.05)
        task.cancel()
        return ws, hub

    ws, hub = asyncio.run(main())
    got = [json.loads(t)["msg_seq"] for t in ws.sent]
    assert got == [1, *range(31, 41)]  # the one in flight, then the newest block
    assert hub.dropped == 29  # 2..30


def test_an_idle_loop_dispatches_each_read_at_once_a_busy_one_gathers():
    async def main() -> tuple[list[int], list[int], int, int]:
        h = History()
        hub = Hub(h, interval_s=0.0)
        hub.attach(asyncio.get_running_loop())
        ws = FakeWS()
        task = asyncio.create_task(hub.register(ws, None, True).run(h, None))
        idle = []
        for _ in range(5):  # the loop is free between reads: one frame per read
            hub.publish_threadsafe(h.append(msgs(3), encode_message))
            await asyncio.sleep(0.005)
            idle.append(len(ws.sent))
        d0 = hub.dispatches
        for _ in range(50):  # the loop is busy (never yields): all gathered, one block
            hub.publish_threadsafe(h.append(msgs(3), encode_message))
        await asyncio.sleep(0.005)
        busy = [len(json.loads(a)) for a in ws.sent[5:]]
        task.cancel()
        return idle, busy, d0, hub.dispatches

    idle, busy, d0, d1 = asyncio.run(main())
    assert idle == [1, 2, 3, 4, 5] and d0 == 5
    assert d1 == d0 + 1 and busy == [150]


def test_a_minimum_spacing_when_ws_batch_interval_s_is_set():
    async def main() -> tuple[float, float, float]:
        h = History()
        hub = Hub(h, interval_s=0.05)
        hub.attach(asyncio.get_running_loop())
        ws = FakeWS()
        task = asyncio.create_task(hub.register(ws, None, True).run(h, None))
        t0 = time.monotonic()
        hub.publish_threadsafe(h.append(msgs(1), encode_message))  # idle for long: at once
        while len(ws.sent) < 1:
            await asyncio.sleep(0.001)
        d1 = hub.last_publish_mono
        hub.publish_threadsafe(h.append(msgs(1), encode_message))  # 50 ms after the first
        hub.publish_threadsafe(h.append(msgs(1), encode_message))
        while len(ws.sent) < 2:
            await asyncio.sleep(0.001)
        task.cancel()
        return t0, d1, hub.last_publish_mono

    t0, d1, d2 = asyncio.run(main())
    assert d1 - t0 < 0.04 and d2 - d1 >= 0.049


def test_alarm_states_coalesce_and_the_newest_goes_out():
    """A flapping limit: 1000 alarm states while a decimated client cannot send; only
    the newest waits, and it is what the client receives when it can send again."""
    async def main() -> tuple[list[int], list[str]]:
        h = History()
        hub = Hub(h, interval_s=0.0)
        hub.attach(asyncio.get_running_loop())
        gate = asyncio.Event()
        ws = FakeWS(gate)
        c = hub.register(ws, 25.0, False)
        task = asyncio.create_task(c.run(h, None))
        waiting = []
        for k in range(1000):
            hub.publish_event_threadsafe(json.dumps({"type": "alarm", "alarms": [k]}))
            hub.publish_threadsafe(h.append(msgs(1), encode_message))
            await asyncio.sleep(0)
            waiting.append(len(c.events) + len(c.queue))
        gate.set()
        await asyncio.sleep(0.1)
        task.cancel()
        return waiting, ws.sent

    waiting, sent = asyncio.run(main())
    assert max(waiting) <= 2  # one alarm state and one (decimated) message
    alarms = [json.loads(t)["alarms"] for t in sent if '"type": "alarm"' in t]
    assert alarms[-1] == [999] and len(alarms) <= 3
    assert json.loads(sent[-1])["msg_seq"] == 1000


def test_fan_out_takes_turns_a_bounded_round_per_loop_iteration():
    """200 one-message-per-frame clients and a 1000-message block: every loop iteration
    sends at most one round (ROUND_SENDS + one quantum), and every client moves on."""
    from radar_io.service.hub import QUANTUM, ROUND_SENDS

    class Counting:
        sends = 0

        def __init__(self) -> None:
            self.n = 0

        async def send(self, msg: dict) -> None:
            self.n += 1
            Counting.sends += 1

    async def main() -> tuple[list[int], list[int]]:
        h = History()
        hub = Hub(h, queue_size=10_000, interval_s=0.0)
        loop = asyncio.get_running_loop()
        hub.attach(loop)
        wss = [Counting() for _ in range(200)]
        tasks = [asyncio.create_task(hub.register(ws, None, False).run(h, None)) for ws in wss]
        await asyncio.sleep(0)
        per_iteration: list[int] = []
        half: list[int] = []
        done = loop.create_future()

        def probe(last: int = 0) -> None:  # runs once per loop iteration
            per_iteration.append(Counting.sends - last)
            if not half and Counting.sends >= 100 * 1000:
                half.extend(ws.n for ws in wss)
            if Counting.sends < 200 * 1000:
                loop.call_soon(probe, Counting.sends)
            else:
                done.set_result(None)

        hub.publish_threadsafe(h.append(msgs(1000, 10), encode_message))
        loop.call_soon(probe)
        await asyncio.wait_for(done, 60)
        for t in tasks:
            t.cancel()
        return per_iteration, half, [ws.n for ws in wss]

    per_iteration, half, end = asyncio.run(main())
    assert max(per_iteration) <= ROUND_SENDS + QUANTUM
    assert max(half) - min(half) <= 2 * QUANTUM  # half way, every client half way
    assert end == [1000] * 200


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
