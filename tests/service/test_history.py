"""The live history: lookups by msg_seq across blocks and byte-bounded eviction, against a
plain list, and consistent pages while the reader thread appends."""

from __future__ import annotations

import json
import random
import threading

from radar_io.service.history import BLOCK, History


def test_since_and_latest_match_a_plain_list_across_blocks_and_eviction():
    h = History(max_bytes=40_000)
    ref: list[tuple[int, str]] = []
    rng = random.Random(3)
    for _ in range(60):
        msgs = [{"v": rng.random()} for _ in range(rng.randint(1, 300))]
        ref += h.append(msgs, json.dumps)
        kept = ref[-len(h):]
        assert h.first_seq == kept[0][0] and h.last_seq == ref[-1][0]
        assert h.nbytes == sum(len(t) for _, t in kept) <= 40_000
        for after in (0, kept[0][0] - 5, kept[0][0] + rng.randint(0, len(kept)), h.last_seq):
            for limit in (None, 1, rng.randint(1, 3 * BLOCK)):
                want = [m for m in kept if m[0] > after][:limit]
                assert h.since(after, limit) == want, (after, limit)
        assert h.latest(700) == kept[-700:]
    assert len(ref) > 3 * BLOCK > len(h)  # several blocks were dropped


def test_pages_stay_contiguous_while_appending():
    h = History(max_bytes=200_000)
    stop = threading.Event()

    def writer() -> None:
        while not stop.is_set():
            h.append([{"k": i} for i in range(50)], json.dumps)

    t = threading.Thread(target=writer)
    t.start()
    try:
        for _ in range(300):
            page = h.since(max(0, h.last_seq - 3000), 2500)
            seqs = [s for s, _ in page]
            assert seqs == list(range(seqs[0], seqs[0] + len(seqs))) if seqs else True
            assert all(json.loads(text)["msg_seq"] == s for s, text in page[:5])
    finally:
        stop.set()
        t.join()
