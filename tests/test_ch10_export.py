"""IRIG 106 Chapter 10 export, read back with pychapter10 (an independent reader).

pychapter10 is a test dependency installed with ``pip install --no-deps pychapter10``
(it pins an old bitstruct that cantools refuses) plus ``bitstring`` (README's test command).
"""

from __future__ import annotations

import json
import random
from itertools import pairwise
from pathlib import Path

import pytest
from conftest import run_cli

from radar_io.benchmarks.ch10 import _utc, read_back
from radar_io.cli.main import main as cli_main
from radar_io.framing.core import Framer
from radar_io.recording.rdrlog import RecordingReader, RecordingWriter
from radar_io.wirespec.frame import load_spec

pytest.importorskip("chapter10", reason="pychapter10 is not installed (README test command: "
                    "pip install --no-deps pychapter10 bitstring)")

GO_MASK, SYNC_MASK = 0x0001, 0x8000   # RDR1 status word: B15 = GO, B0 = SYNC (msb0)
STEP_NS = 7_250_000_000               # wall clock set forward in the crafted recording
GAP_NS = 3_500_000_000                # nothing received for 3.5 s


@pytest.fixture(scope="module")
def sim_rec(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rec = tmp_path_factory.mktemp("ch10") / "sim.rdrlog"
    assert cli_main(["simulate", "-o", str(rec), "--duration-s", "12", "--sync-every-s", "2",
                     "-q"]) == 0
    return rec


@pytest.fixture(scope="module")
def crafted(sim_rec: Path) -> tuple[Path, list[dict]]:
    """The simulated chunks with a receive gap, a wall-clock step, a 700-kB chunk (beyond
    the message and packet limits) and an event log with annotations, an alarm, a record
    without time and a bad line."""
    with RecordingReader(sim_rec) as r:
        chunks = [(c.t_ns, c.mono_ns, c.data) for c in r]
    rec = sim_rec.with_name("crafted.rdrlog")
    n = len(chunks)
    big = random.Random(7).randbytes(700_001)
    out = []
    with RecordingWriter(rec, load_spec(), source="/dev/radar?baudrate=115200") as w:
        for i, (t, m, d) in enumerate(chunks):
            if i >= n // 3:
                t, m = t + GAP_NS, m + GAP_NS
            if i >= 2 * n // 3:
                t += STEP_NS
            if i == n // 2:
                w.write(big, t - 1_000_000, m - 1_000_000)
                out.append((t - 1_000_000, m - 1_000_000, big))
            w.write(d, t, m)
            out.append((t, m, d))
    t_a, m_a = out[n // 6][0] + 123_400, out[n // 6][1] + 123_400
    records = [
        {"kind": "annotation", "annotation_kind": "test_point_start", "label": "TP4",
         "text": "wind-up turn; 250 kt", "t_ns": t_a},
        {"kind": "annotation", "annotation_kind": "test_point_end", "label": "TP4",
         "t_ns": t_a + 2_000_000_000, "mono_ns": m_a + 2_000_000_000},
        {"type": "alarm", "action": "raise", "name": "dy", "t_s": (t_a + 500_000_000) / 1e9},
        {"kind": "annotation", "label": "no time"},
    ]
    ev = rec.with_suffix(".events.jsonl")
    ev.write_text("".join(json.dumps(r) + "\n" for r in records) + "{not json\n")
    return rec, records


def expected_edges(rec: Path) -> list[tuple[str, int]]:
    """GO and SYNC edges found with the per-frame framer, at their chunk's receive time."""
    framer = Framer(load_spec())
    prev: dict[str, int | None] = {"GO": None, "SYNC": None}
    out = []
    with RecordingReader(rec) as r:
        for c in r:
            for frame in framer.feed(c.data):
                sts = int.from_bytes(frame[20:22], "big")
                for name, mask in (("GO", GO_MASK), ("SYNC", SYNC_MASK)):
                    v = int(bool(sts & mask))
                    if prev[name] is not None and v != prev[name]:
                        if name == "GO":
                            out.append(("GO_ON" if v else "GO_OFF", c.t_ns))
                        elif v:
                            out.append(("SYNC", c.t_ns))
                    prev[name] = v
    return out


def near(events: list, name: str, t_ns: int) -> bool:
    """An event ``name`` within 2 µs of ``t_ns`` (a float t_s is good to about 0.5 µs)."""
    return any(n == name and abs((t - _utc(t_ns)).total_seconds()) <= 2e-6 for n, t in events)


def test_export_reads_back_with_pychapter10(sim_rec: Path) -> None:
    out = sim_rec.with_suffix(".ch10")
    r = run_cli("export", str(sim_rec), "-o", str(out))
    assert r.returncode == 0, r.stderr
    b = read_back(sim_rec, out)   # checksums, bytes, one message per chunk, times (raises)
    assert b["uart_messages"] == b["chunks"] > 500
    assert b["types"]["0x01"] == 1 and b["types"]["0x02"] >= 1
    # a time packet at every whole second of the span, one second apart
    rtc, times = zip(*b["time_packets_rtc"], strict=True)
    assert len(times) == b["span_seconds"] >= 12
    assert all((t1 - t0).total_seconds() == 1.0 for t0, t1 in pairwise(times))
    assert {r1 - r0 for r0, r1 in pairwise(rtc)} == {10_000_000}   # 1 s of the 10-MHz RTC
    assert times[0].microsecond == 0
    edges = expected_edges(sim_rec)
    assert [n for n, _ in edges].count("SYNC") >= 4 and edges[0][0] == "GO_ON"
    assert [(n, t) for n, t in b["event_times"]] == [(n, _utc(t)) for n, t in edges]
    assert "R-1\\CDT-2:UARTIN;" in b["tmats"] and "R-1\\EV\\ID-3:SYNC;" in b["tmats"]
    assert not list(sim_rec.parent.glob(".*.part"))


def test_gap_clock_step_big_chunk_and_event_log(crafted: tuple[Path, list[dict]]) -> None:
    rec, records = crafted
    out = rec.with_suffix(".ch10")
    r = run_cli("export", str(rec), "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "1 event-log records without a time" in r.stderr.decode()
    b = read_back(rec, out)
    # the 700-kB chunk: 11 messages (65 535 bytes each at most) in 2 packets
    assert b["uart_messages"] == b["chunks"] - 1 + 11
    assert b["max_time_error_us"] <= 1.0
    # the gap is covered second by second (RTC); the step shows as one jump of the wall
    # clock against the RTC, at a time packet of its own
    rtc, times = zip(*b["time_packets_rtc"], strict=True)
    assert max(r1 - r0 for r0, r1 in pairwise(rtc)) <= 10_000_000
    jumps = [(t1 - t0).total_seconds() - (r1 - r0) / 1e7
             for (r0, t0), (r1, t1) in pairwise(b["time_packets_rtc"])]
    big = [j for j in jumps if abs(j) > 1e-5]
    assert big == [pytest.approx(STEP_NS / 1e9, abs=1e-5)]
    assert len(times) >= (b["span_seconds"] - STEP_NS // 10**9)
    assert "R-1\\UCR-2-1:115200;" in b["tmats"]
    assert "R-1\\EV\\D-7:test_point_start: wind-up turn, 250 kt;" in b["tmats"]
    got = b["event_times"]
    want = [(n, _utc(t)) for n, t in expected_edges(rec)]
    assert [e for e in got if e[0] in ("GO_ON", "GO_OFF", "SYNC")] == want
    assert near(got, "TP4", records[0]["t_ns"]) and near(got, "TP4", records[1]["t_ns"])
    assert near(got, "ALARM", int(records[2]["t_s"] * 1e9))
    assert [n for n, _ in got].count("CLOCK_STEP") == 1


def test_decode_to_ch10_is_the_export(sim_rec: Path, tmp_path: Path) -> None:
    a, b = tmp_path / "a.ch10", tmp_path / "b.ch10"
    assert run_cli("export", str(sim_rec), "-o", str(a), "-q").returncode == 0
    r = run_cli("decode", str(sim_rec), "-o", str(b), "-q")
    assert r.returncode == 0, r.stderr
    assert a.read_bytes() == b.read_bytes()
    r = run_cli("export", str(sim_rec), "-o", str(a), "--events", str(tmp_path / "none.jsonl"))
    assert r.returncode == 2 and b"event log not found" in r.stderr


def test_export_refuses_a_raw_capture(tmp_path: Path) -> None:
    raw = tmp_path / "capture.bin"
    raw.write_bytes(b"\xeb\x90" * 100)
    out = tmp_path / "x.ch10"
    r = run_cli("export", str(raw), "-o", str(out))
    assert r.returncode == 2
    assert r.stderr.decode().count("\n") == 1 and "needs a .rdrlog" in r.stderr.decode()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture.bin"]
    r = run_cli("export", str(tmp_path / "missing.rdrlog"))
    assert r.returncode == 2 and b"input not found" in r.stderr



def test_clock_set_back_between_chunks_2_ms_apart(tmp_path: Path) -> None:
    """The step's time packet keeps the RTC increasing and every chunk's time exact."""
    rec, out = tmp_path / "close.rdrlog", tmp_path / "close.ch10"
    t0, m0 = 1_800_000_000_123_456_789, 5_000_000_000
    with RecordingWriter(rec, load_spec()) as w:
        for k in range(3000):  # 6 s of 2-ms chunks; the wall clock set back 3.3 s halfway
            w.write(bytes([k % 256]) * 7, t0 + k * 2_000_000 - (k >= 1500) * 3_300_000_000,
                    m0 + k * 2_000_000)
    assert run_cli("export", str(rec), "-o", str(out), "-q").returncode == 0
    b = read_back(rec, out)
    assert b["uart_messages"] == 3000 and b["max_time_error_us"] <= 1.0
    rtc = [r for r, _ in b["time_packets_rtc"]]
    assert rtc == sorted(set(rtc))
    assert b["events"] == {"CLOCK_STEP": 1}
