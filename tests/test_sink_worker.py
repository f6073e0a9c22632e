"""SinkWorker: a batch that cannot be encoded is counted and dropped, the link stays up; a
link that fails is closed and reopened with back-off."""

from __future__ import annotations

import time

import numpy as np
import pytest

from radar_io.errors import UplinkError, ValidationError
from radar_io.sinks.base import Sink
from radar_io.sinks.worker import SinkWorker


class ListSink(Sink):
    """A sink that keeps what it is given; ``fail`` maps a batch's first seq to an error."""

    def __init__(self, fail: dict[int, Exception]) -> None:
        super().__init__("list://")
        self.fail, self.rows, self.opens, self.closes = fail, [], 0, 0

    def open(self) -> None:
        self.opens += 1

    def write(self, batch) -> int:
        first = int(batch["seq"][0])
        exc = self.fail.pop(first, None)
        if exc is not None:
            raise exc
        self.rows.extend(int(s) for s in batch["seq"])
        return len(batch["seq"])

    def close(self) -> None:
        self.closes += 1


def _wait(cond, timeout_s: float = 10.0) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.01)


def _feed(worker: SinkWorker, seqs: list[int]) -> None:
    for s in seqs:
        worker.submit([{"seq": s, "sr_m": float(s)}])
        time.sleep(0.02)  # one batch each, in order


def test_an_unencodable_batch_is_dropped_without_a_reconnect():
    sink = ListSink({2: ValidationError("needs column dy_m")})
    w = SinkWorker("t", sink)
    try:
        _feed(w, [1, 2, 3, 4])
        _wait(lambda: sink.rows[-1:] == [4])
        st = w.stats()
        assert sink.rows == [1, 3, 4]
        assert (st["errors"], st["reconnects"], st["dropped_samples"]) == (1, 0, 1)
        assert st["connected"] and sink.opens == 1 and "dy_m" in st["last_error"]
    finally:
        w.close()


def test_a_failed_link_is_reopened_and_counted():
    sink = ListSink({2: UplinkError("write failed: EIO")})
    w = SinkWorker("t", sink)
    try:
        _feed(w, [1, 2])
        _wait(lambda: w.stats()["reconnects"] == 1 and w.connected)
        _feed(w, [5])
        _wait(lambda: sink.rows[-1:] == [5])
        assert sink.opens == 2 and sink.closes >= 1 and 2 not in sink.rows
        assert np.isin([1, 5], sink.rows).all()
    finally:
        w.close()


class RefusingLink(ListSink):
    """Opens every time, but every write fails (a UDP peer answering ECONNREFUSED)."""

    def write(self, batch) -> int:
        raise UplinkError("write: connection refused")


@pytest.mark.slow
def test_the_back_off_grows_while_writes_keep_failing():
    sink = RefusingLink({})
    w = SinkWorker("t", sink)
    try:
        for s in range(400):
            w.submit([{"seq": s, "sr_m": 0.0}])
            time.sleep(0.005)
        # 0.1 + 0.2 + 0.4 + 0.8 s of back-off fit in the 2 s: at most ~5 reopens, not 20
        assert 2 <= sink.opens <= 6, sink.opens
    finally:
        w.close()


def test_fan_out_builds_the_columns_once_and_every_worker_gets_them(monkeypatch):
    from radar_io.sinks import worker as worker_mod

    calls = []
    real = worker_mod.message_columns
    monkeypatch.setattr(worker_mod, "message_columns", lambda msgs: calls.append(1) or real(msgs))
    sinks = [ListSink({}), ListSink({})]
    workers = [SinkWorker(f"w{i}", s) for i, s in enumerate(sinks)]
    try:
        submit = worker_mod.fan_out(workers)
        submit([{"seq": 1, "sr_m": 1.0}, {"seq": 2, "sr_m": None}])
        submit([{"seq": 3, "sr_m": 3.0}])
        _wait(lambda: all(s.rows == [1, 2, 3] for s in sinks))
        assert len(calls) == 2  # once per read, not once per worker
    finally:
        for w in workers:
            w.close()
