"""Chapter 10 export: read back with an independent reader, and the export's time and memory.

``python -m radar_io.benchmarks.ch10 [--minutes 10] [--hours 1]``

1. Simulates a ``--minutes`` recording at 1 kHz, exports it (``radar-io export``) and reads
   the file back with ``pychapter10`` (:func:`read_back`): every packet's header and data
   checksum, the UART payloads against the recording's bytes, one message per chunk, the
   time packets and every message's time against its chunk's ``t_ns``, the events.
2. Simulates a ``--hours`` recording and times ``radar-io export`` of it in a fresh child
   process (wall, CPU, peak RSS = the child's ``ru_maxrss``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shutil
import struct
import sys
import tempfile
from pathlib import Path
from typing import Any

from radar_io.errors import ValidationError


def _utc(t_ns: int) -> dt.datetime:
    """A naive UTC datetime (pychapter10's time representation), µs resolution."""
    return dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=t_ns // 1000)


def read_back(recording: str | Path, ch10: str | Path) -> dict[str, Any]:
    """Read ``ch10`` with pychapter10 and compare it with ``recording``; a summary.

    Raises ValidationError at the first disagreement (naming the packet)."""
    # a test dependency, installed by the README's test command (--no-deps pychapter10)
    from chapter10 import C10

    from radar_io.recording.rdrlog import RecordingReader

    raw = Path(ch10).read_bytes()
    with RecordingReader(recording) as r:
        chunks = [(c.t_ns, c.data) for c in r]

    def fail(msg: str) -> None:
        raise ValidationError(f"{ch10}: {msg}")

    off = 0
    types: dict[str, int] = {}
    tmats = ""
    time_packets: list[tuple[int, dt.datetime]] = []
    uart: list[tuple[int, bytes, dt.datetime]] = []   # ipts, data, time from pychapter10
    events: list[tuple[int, int, int, dt.datetime]] = []  # number, count, ipts, time
    max_dt_us = 0.0
    for i, p in enumerate(C10(str(ch10))):
        if p.packet_length % 4 or off + p.packet_length > len(raw):
            fail(f"packet {i} at byte {off}: bad length {p.packet_length}")
        head = raw[off:off + 24]
        if struct.unpack("<H", head[:2])[0] != 0xEB25 or \
                sum(struct.unpack("<11H", head[:22])) & 0xFFFF != struct.unpack("<H", head[22:])[0]:
            fail(f"packet {i} at byte {off}: sync or header checksum wrong")
        if p.data_checksum != 3 or p.secondary_header:
            fail(f"packet {i}: flags {p.data_checksum=} {p.secondary_header=}")
        body = raw[off + 24:off + p.packet_length - 4]
        words = struct.unpack(f"<{len(body) // 4}I", body)
        if sum(words) & 0xFFFFFFFF != struct.unpack("<I", raw[off + p.packet_length - 4:
                                                              off + p.packet_length])[0]:
            fail(f"packet {i} at byte {off}: data checksum wrong")
        key = f"0x{p.data_type:02x}"
        types[key] = types.get(key, 0) + 1
        if (i == 0 and p.data_type != 0x01) or (i == 1 and p.data_type != 0x11):
            fail("the first packets are not TMATS then time")
        if p.data_type == 0x01:
            tmats = p.data.decode("ascii")
        elif p.data_type == 0x11:
            time_packets.append((p.rtc, p.time))
        elif p.data_type == 0x50:
            for m in p:
                uart.append((m.ipts, bytes(m.data), m.get_time()))
        elif p.data_type == 0x02:
            # entries read from the bytes: pychapter10 1.1.19 unpacks the entry word's
            # 12/16-bit fields with byte-swapped bit order (event 1 comes out as 257)
            n = struct.unpack("<I", body[:4])[0] & 0xFFF
            for k in range(n):
                ipts, entry = struct.unpack("<QI", body[4 + 12 * k:16 + 12 * k])
                t = time_packets[-1][1] + dt.timedelta(
                    microseconds=(ipts - time_packets[-1][0]) // 10)
                events.append((entry & 0xFFF, (entry >> 12) & 0xFFFF, ipts, t))
        off += p.packet_length
    if off != len(raw):
        fail(f"packets cover {off} of {len(raw)} bytes (a packet was skipped)")
    # UART: the bytes in order, one message per chunk (split only beyond 65 535 bytes)
    if b"".join(d for _, d, _ in uart) != b"".join(d for _, d in chunks):
        fail("UART payloads differ from the recording's bytes")
    k = 0
    for ci, (t_ns, data) in enumerate(chunks):
        pieces = max(1, -(-len(data) // 65535))
        got = uart[k:k + pieces]
        if b"".join(d for _, d, _ in got) != data or len({ip for ip, _, _ in got}) != 1:
            fail(f"chunk {ci}: not {pieces} message(s) with one time stamp")
        dt_us = abs((got[0][2] - _utc(t_ns)).total_seconds()) * 1e6
        max_dt_us = max(max_dt_us, dt_us)
        if dt_us > 2.0:
            fail(f"chunk {ci}: message time {got[0][2]} is not its receive time {_utc(t_ns)}")
        k += pieces
    if k != len(uart):
        fail(f"{len(uart)} UART messages for {len(chunks)} chunks")
    # time packets: every second of the span (more only where the wall clock stepped)
    first_s, last_s = chunks[0][0] // 10**9, chunks[-1][0] // 10**9
    names = {}
    for line in tmats.split(";"):
        code, _, value = line.strip().partition(":")
        if code.startswith("R-1\\EV\\ID-"):
            names[int(code.rsplit("-", 1)[1])] = value
    counts: dict[str, int] = {}
    for num, _, _, _ in events:
        counts[names.get(num, str(num))] = counts.get(names.get(num, str(num)), 0) + 1
    return {"packets": sum(types.values()), "bytes": len(raw), "types": types,
            "chunks": len(chunks), "uart_messages": len(uart),
            "recorded_bytes": sum(len(d) for _, d in chunks),
            "time_packets": len(time_packets), "span_seconds": last_s - first_s + 1,
            "time_packets_rtc": time_packets,
            "max_time_error_us": max_dt_us, "events": counts,
            "event_times": [(names.get(n, str(n)), t) for n, _, _, t in events],
            "tmats": tmats}


def _first_t_ns(rec: Path) -> int:
    from radar_io.recording.rdrlog import RecordingReader

    with RecordingReader(rec) as r:
        return next(iter(r)).t_ns


def run(minutes: float = 10.0, hours: float = 1.0, workdir: str | None = None) -> dict[str, Any]:
    """The read-back of a ``minutes`` recording and the export figures of an ``hours`` one."""
    from radar_io.benchmarks.outputs import _run_child, make_recording

    tmp = Path(workdir or tempfile.mkdtemp(prefix="radar-io-bench-ch10-"))
    tmp.mkdir(parents=True, exist_ok=True)
    res: dict[str, Any] = {"minutes": minutes, "hours": hours}
    try:
        # the timed export first: a child's ru_maxrss includes the parent's RSS at fork,
        # and the read-back below holds a recording in memory
        if hours > 0:
            rec = tmp / "hour.rdrlog"
            if not rec.exists():
                make_recording(rec, hours)
            res["recording_mb"] = rec.stat().st_size / 1e6
            out = tmp / "hour.ch10"
            res["export_s"], res["export_cpu_s"], res["export_rss_mb"] = _run_child(
                ["-m", "radar_io.cli", "export", str(rec), "-o", str(out), "-q"])
            res["ch10_mb"] = out.stat().st_size / 1e6
            out.unlink()
        if minutes > 0:
            rec = tmp / "short.rdrlog"
            if not rec.exists():
                make_recording(rec, minutes / 60.0)
            first_t_ns = _first_t_ns(rec)
            notes: list[dict[str, Any]] = [{"kind": "annotation", "annotation_kind": kind, "label": label,
                      "text": f"{label} {kind}", "t_ns": first_t_ns + int(at_s * 1e9)}
                     for label, kind, at_s in (("TP1", "test_point_start", 60.25),
                                               ("TP1", "test_point_end", 150.5),
                                               ("TP2", "test_point_start", 300.125),
                                               ("TP2", "test_point_end", 420.0),
                                               ("M1", "marker", 500.0))]
            rec.with_suffix(".events.jsonl").write_text(
                "".join(json.dumps(n) + "\n" for n in notes))
            out = tmp / "short.ch10"
            res["short_export_s"], res["short_export_cpu_s"], res["short_export_rss_mb"] = \
                _run_child(["-m", "radar_io.cli", "export", str(rec), "-o", str(out), "-q"])
            back = read_back(rec, out)
            # each annotation once, at its time (µs: pychapter10's datetime resolution)
            errs = [min(abs((t - _utc(n["t_ns"])).total_seconds()) * 1e6
                        for name, t in back["event_times"] if name == n["label"])
                    for n in notes]
            back["annotation_max_error_us"] = max(errs)
            res["read_back"] = {k: v for k, v in back.items()
                                if k not in ("time_packets_rtc", "event_times", "tmats")}
    finally:
        if workdir is None:
            shutil.rmtree(tmp, ignore_errors=True)
    return res


def report(res: dict[str, Any]) -> str:
    lines = []
    if "read_back" in res:
        b = res["read_back"]
        lines.append(
            f"ch10 {res['minutes']:g}-min recording: export {res['short_export_s']:.1f} s, "
            f"read back with pychapter10: {b['packets']} packets {b['types']} all checksums "
            f"valid; {b['uart_messages']} UART messages for {b['chunks']} chunks, "
            f"{b['recorded_bytes']} bytes identical; {b['time_packets']} time packets over a "
            f"{b['span_seconds']}-s span; message times within {b['max_time_error_us']:.2f} us "
            f"of t_ns; events {b['events']} (annotations within "
            f"{b['annotation_max_error_us']:.2f} us of their t_ns)")
    if "export_s" in res:
        lines.append(f"ch10 export of a {res['hours']:g}-h recording ({res['recording_mb']:.0f} MB"
                     f" -> {res['ch10_mb']:.0f} MB): {res['export_s']:.1f} s wall, "
                     f"{res['export_cpu_s']:.1f} s CPU, peak RSS {res['export_rss_mb']:.0f} MB")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m radar_io.benchmarks.ch10",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=10.0, help="read-back recording; 0 skips")
    p.add_argument("--hours", type=float, default=1.0, help="timed recording; 0 skips")
    p.add_argument("--workdir", help="keep the recordings here (reused on the next run)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    res = run(args.minutes, args.hours, args.workdir)
    print(json.dumps(res, indent=2, default=str) if args.json else report(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
