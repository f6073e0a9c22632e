"""IRIG 106 Chapter 10 files from a recording's received chunks (``radar-io export``).

The packet layouts are those of IRIG 106-17 Chapter 11 (before 106-17 they were in
Chapter 10); ``docs/chapter10.md`` restates what is written here and cites the sections.
In short, all little-endian, every packet 4-byte aligned with a 32-bit data checksum and
no secondary header:

* channel 0, data type 0x01: the computer-generated TMATS setup record (first packet);
* channel 1, data type 0x11: a time packet (format 1, day-month-year BCD) at every whole
  second of the recording's wall clock across its span, gaps included;
* channel 2, data type 0x50: UART format 0 packets, one UART message per received chunk
  (split only at the 65 535-byte message or the 524 288-byte packet limit), each with an
  intra-packet time stamp = the relative time counter (RTC, 10 MHz) at the chunk's
  monotonic receive time; a packet holds at most 100 ms of chunks;
* channel 0, data type 0x02: recording events (GO 0→1 / 1→0, SYNC 0→1, wall-clock steps,
  alarms, annotations), each defined in the TMATS (``R-1\\EV\\…``).

The RTC runs on the recording's monotonic clock (``mono_ns``); time packets tie it to the
wall clock (``t_ns``): a wall-clock step gets a time packet of its own at the chunk where
it shows, so every chunk's stamp converts back to its ``t_ns``.
"""

from __future__ import annotations

import datetime as dt
import os
import re
import struct
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from radar_io.errors import RecordingError
from radar_io.sinks.atomic import AtomicStream
from radar_io.sinks.base import Batch, Sink

SYNC_PATTERN = 0xEB25
#: packet header data type version: 0x08 = RCC 106-17 (§11.2.1.1 e)
DATA_TYPE_VERSION = 0x08
#: setup record channel-specific data word, IRIG 106 version: 0x0C = RCC 106-17
TMATS_VERSION = 0x0C
#: packet flags: no secondary header, IPTS = header RTC, data checksum 32-bit (bits 1-0 = 11)
PACKET_FLAGS = 0x03
MAX_PACKET_BYTES = 524_288
MAX_UART_MESSAGE_BYTES = 65_535
MAX_EVENTS_PER_PACKET = 4095          # 12-bit entry count in the event CSDW
UART_PACKET_SPAN_NS = 100_000_000     # at most 100 ms of chunks per UART packet
RTC_TICK_NS = 100                     # 10 MHz
RTC_MASK = (1 << 48) - 1
#: a change of (t_ns - mono_ns) between chunks beyond this is a wall-clock step
CLOCK_STEP_NS = 1_000_000
#: time packet CSDW: date format 1 (day, month, year), format 0x3 (real-time clock),
#: source 0x0 (internal: the recording host's clock)
TIME_FORMAT_RTC = 0x3
TIME_SOURCE_INTERNAL = 0x0

CHANNEL_COMPUTER = 0
CHANNEL_TIME = 1
CHANNEL_UART = 2

DT_TMATS = 0x01
DT_EVENT = 0x02
DT_TIME_F1 = 0x11
DT_UART_F0 = 0x50

_HEAD = struct.Struct("<HHIIBBBB")    # sync, channel, packet length, data length, version,
                                      # sequence, flags, data type (then 6-byte RTC, checksum)
_IPH_UART = struct.Struct("<QI")      # intra-packet time stamp, intra-packet data header
_EVENT = struct.Struct("<QI")         # intra-packet time stamp, event entry


@dataclass(frozen=True)
class EventDef:
    """One recording event definition: the number in the packets and the TMATS text."""

    number: int
    ident: str
    description: str
    kind: str = "E"             # R-x\EV\T: D measurement discrete, E external, R recorder
    measurement: str = ""


#: the fixed event numbers; each annotation gets the next free one. An event's number is
#: its definition's place n in the TMATS (``R-1\\EV\\ID-n``)
GO_ON, GO_OFF, SYNC_ON, CLOCK_STEP, ALARM, ANNOTATION = 1, 2, 3, 4, 5, 6
FIXED_EVENTS = (
    EventDef(GO_ON, "GO_ON", "GO 0 to 1 (system start) in the RDR1 status word", "D", "GO"),
    EventDef(GO_OFF, "GO_OFF", "GO 1 to 0 (system stop) in the RDR1 status word", "D", "GO"),
    EventDef(SYNC_ON, "SYNC", "SYNC 0 to 1 (transponder sync, camera shutter) in the RDR1 "
             "status word", "D", "SYNC"),
    EventDef(CLOCK_STEP, "CLOCK_STEP", "wall-clock step of the recording host", "R"),
    EventDef(ALARM, "ALARM", "limit alarm raised, cleared or acknowledged", "E"),
    EventDef(ANNOTATION, "ANNOTATION", "operator annotation", "E"),
)
ANNOTATION_KINDS = ("note", "test_point_start", "test_point_end", "marker")


def header_checksum(head22: bytes) -> int:
    """Arithmetic sum of the header's first eleven 16-bit words, modulo 2^16."""
    return sum(struct.unpack("<11H", head22)) & 0xFFFF


def data_checksum32(body: bytes | bytearray | memoryview) -> int:
    """Arithmetic sum of the body's 32-bit words (length a multiple of 4), modulo 2^32."""
    return int(np.frombuffer(body, dtype="<u4").sum(dtype=np.uint64)) & 0xFFFFFFFF


def encode_packet(channel: int, data_type: int, sequence: int, rtc: int,
                  body: bytes | bytearray) -> bytes:
    """One packet: header, ``body`` (CSDW + data), filler to 4 bytes, 32-bit data checksum."""
    data_length = len(body)
    filled = bytes(body) + b"\0" * (-data_length % 4)
    packet_length = 24 + len(filled) + 4
    if packet_length > MAX_PACKET_BYTES and data_type != DT_TMATS:
        raise RecordingError(f"Chapter 10 packet of {packet_length} bytes exceeds "
                             f"{MAX_PACKET_BYTES}")
    head = _HEAD.pack(SYNC_PATTERN, channel, packet_length, data_length, DATA_TYPE_VERSION,
                      sequence & 0xFF, PACKET_FLAGS, data_type) + (rtc & RTC_MASK).to_bytes(6, "little")
    return b"".join((head, struct.pack("<H", header_checksum(head)), filled,
                     struct.pack("<I", data_checksum32(filled))))


def _bcd(v: int) -> tuple[int, int]:
    return v // 10, v % 10


def time_body(t_ns: int) -> bytes:
    """A time data format 1 body: CSDW and day-month-year BCD time (10 ms resolution)."""
    sec, ns = divmod(t_ns, 1_000_000_000)
    d = dt.datetime.fromtimestamp(sec, tz=dt.UTC)
    ms = ns // 1_000_000
    leap = int(d.year % 4 == 0 and (d.year % 100 != 0 or d.year % 400 == 0))
    csdw = (1 << 9) | (leap << 8) | (TIME_FORMAT_RTC << 4) | TIME_SOURCE_INTERNAL
    ts, s = _bcd(d.second)
    tm, m = _bcd(d.minute)
    th, h = _bcd(d.hour)
    td, dd = _bcd(d.day)
    to, mo = _bcd(d.month)
    words = (
        (ts << 12) | (s << 8) | ((ms // 100) << 4) | (ms // 10 % 10),
        (th << 12) | (h << 8) | (tm << 4) | m,
        (to << 12) | (mo << 8) | (td << 4) | dd,
        ((d.year // 1000) << 12) | ((d.year // 100 % 10) << 8) | ((d.year // 10 % 10) << 4)
        | (d.year % 10),
    )
    return struct.pack("<I4H", csdw, *words)


def _tmats_value(text: str) -> str:
    """A TMATS attribute value: no ';' (the terminator), one line, printable ASCII."""
    text = " ".join(str(text).replace(";", ",").split())
    return text.encode("ascii", "replace").decode("ascii")


def tmats_text(*, origin_utc: dt.datetime, recording: str, baud: int | None,
               events: Iterable[EventDef], software: str) -> str:
    """The computer-generated setup record (TMATS, Chapter 9 attributes) for this export."""
    ev = list(events)
    lines = [
        ("G\\PN", "radar_io export"),
        ("G\\106", "17"),
        ("G\\OD", origin_utc.strftime("%m-%d-%Y")),
        ("G\\DSI\\N", "1"),
        ("G\\DSI-1", "RADAR"),
        ("G\\DST-1", "STO"),
        ("G\\COM", f"{software}: RDR1 radar serial stream of {recording}, time packets "
                   + "from the recording host's clock"),
        ("R-1\\ID", "RADAR"),
        ("R-1\\N", "2"),
        # channel 1: time
        ("R-1\\TK1-1", str(CHANNEL_TIME)),
        ("R-1\\DSI-1", "TIME"),
        ("R-1\\CHE-1", "T"),
        ("R-1\\CDT-1", "TIMEIN"),
        ("R-1\\CDLN-1", "TIME"),
        ("R-1\\TTF-1", "1"),
        ("R-1\\TSRC-1", "I"),
        # channel 2: the RDR1 serial line
        ("R-1\\TK1-2", str(CHANNEL_UART)),
        ("R-1\\DSI-2", "RDR1"),
        ("R-1\\CHE-2", "T"),
        ("R-1\\CDT-2", "UARTIN"),
        ("R-1\\CDLN-2", "RDR1"),
        ("R-1\\UTF-2", "0"),
        ("R-1\\NUS\\N-2", "1"),
        ("R-1\\USCN-2-1", "0"),
        ("R-1\\UCNM-2-1", "RDR1"),
    ]
    if baud:
        lines.append(("R-1\\UCR-2-1", str(baud)))
    lines += [("R-1\\UCB-2-1", "8"), ("R-1\\UCP-2-1", "N"), ("R-1\\UCS-2-1", "1"),
              ("R-1\\EV\\E", "T"), ("R-1\\EV\\TK1", str(CHANNEL_COMPUTER)),
              ("R-1\\EV\\N", str(len(ev))), ("R-1\\EV\\IEE", "F")]
    for e in ev:
        n = e.number
        lines += [(f"R-1\\EV\\ID-{n}", e.ident), (f"R-1\\EV\\D-{n}", e.description),
                  (f"R-1\\EV\\EDP-{n}", "F"), (f"R-1\\EV\\T-{n}", e.kind),
                  (f"R-1\\EV\\P-{n}", "1"), (f"R-1\\EV\\IC-{n}", "F")]
        if e.measurement:
            lines.append((f"R-1\\EV\\MN-{n}", e.measurement))
    return "".join(f"{k}:{_tmats_value(v)};\r\n" for k, v in lines)


@dataclass
class FileEvent:
    """An event read from ``REC.events.jsonl``: its time and its event number."""

    mono_ns: int | None
    t_ns: int | None
    number: int


def _event_time(rec: Mapping[str, Any]) -> tuple[int | None, int | None]:
    mono = rec.get("mono_ns")
    t = rec.get("t_ns")
    if t is None and isinstance(rec.get("t_s"), (int, float)):
        t = round(rec["t_s"] * 1e9)

    def ok(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool)

    return (mono if ok(mono) else None), (t if ok(t) else None)


def parse_events(records: Iterable[Mapping[str, Any]]) -> tuple[list[EventDef], list[FileEvent],
                                                                 set[str], int]:
    """Event definitions and timed events from event-log records.

    A record names its kind in ``kind`` (or ``type``, as the alarm log writes it):
    ``go`` (``value``/``state`` 0 or ``edge`` "fall" = 1→0, else 0→1), ``sync``,
    ``clock_step``, ``alarm``, ``annotation`` (or an annotation kind itself: note,
    test_point_start, test_point_end, marker). Time: ``mono_ns``, else ``t_ns`` or ``t_s``
    (wall clock). Each annotation gets a definition of its own (label, kind and text in
    the TMATS) while numbers last. Returns (definitions, events, kinds seen, records
    skipped for want of a time or a known kind).
    """
    defs = list(FIXED_EVENTS)
    events: list[FileEvent] = []
    kinds: set[str] = set()
    skipped = 0
    for rec in records:
        kind = str(rec.get("kind") or rec.get("type") or "")
        mono, t = _event_time(rec)
        if mono is None and t is None:
            skipped += 1
            continue
        if kind == "go":
            low = rec.get("edge") in ("fall", "falling") or rec.get("value", rec.get("state")) in (0, False)
            number = GO_OFF if low else GO_ON
        elif kind == "sync":
            number = SYNC_ON
        elif kind == "clock_step":
            number = CLOCK_STEP
        elif kind == "alarm":
            number = ALARM
        elif kind == "annotation" or kind in ANNOTATION_KINDS:
            nested = rec.get("annotation")
            sub: Mapping[str, Any] = nested if isinstance(nested, Mapping) else rec
            akind = str(sub.get("annotation_kind") or (kind if kind != "annotation" else "")
                        or sub.get("subkind") or "note")
            label = str(sub.get("label") or akind)
            number = len(defs) + 1
            if number <= 0xFFF:  # the entry's 12-bit event number
                text = str(sub.get("text") or "")
                defs.append(EventDef(number, label, f"{akind}: {text}" if text else akind, "E"))
            else:
                number = ANNOTATION
            kind = "annotation"
        else:
            skipped += 1
            continue
        kinds.add(kind)
        events.append(FileEvent(mono, t, number))
    return defs, events, kinds, skipped


def read_events_file(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The JSON-object lines of an event log (missing file: none; bad lines skipped)."""
    import json

    out: list[dict[str, Any]] = []
    try:
        with open(path, encoding="utf-8") as f:
            for line in f:
                try:
                    rec = json.loads(line)
                except ValueError:
                    continue
                if isinstance(rec, dict):
                    out.append(rec)
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise RecordingError(f"cannot read event log {path}: {exc.strerror}") from exc
    return out


@dataclass
class Ch10Stats:
    """What an export wrote."""

    packets: int = 0
    bytes: int = 0
    time_packets: int = 0
    uart_packets: int = 0
    uart_messages: int = 0
    uart_bytes: int = 0
    chunks: int = 0
    event_packets: int = 0
    events: dict[str, int] = field(default_factory=dict)
    clock_steps: int = 0
    events_skipped: int = 0

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class Ch10Writer(Sink):
    """A Chapter 10 file written chunk by chunk (memory flat), complete only after close.

    ``write_chunk(t_ns, mono_ns, data)`` takes the received chunks in order;
    ``write(batch)`` takes a batch of them (columns ``t_ns``, ``mono_ns``, ``data``).
    GO and SYNC edges are found in the chunks' RDR1 frames (``spec``) unless ``events``
    (event-log records) already hold them; wall-clock steps likewise.
    """

    format = "ch10"
    reopen = False

    def __init__(self, target: str | os.PathLike[str], *, spec: Any = None,
                 events: Iterable[Mapping[str, Any]] = (), recording: str = "",
                 baud: int | None = None, software: str = "", **_: Any) -> None:
        super().__init__(os.fspath(target))
        from radar_io.framing.core import BatchFramer
        from radar_io.wirespec.frame import load_spec

        self.spec = spec if spec is not None else load_spec()
        self.defs, events_in, kinds, skipped = parse_events(events)
        self._file_events = events_in  # sorted by time once the clock offset is known
        self._derive_edges = not kinds & {"go", "sync"}
        self._derive_steps = "clock_step" not in kinds
        self._framer = BatchFramer(self.spec) if self._derive_edges else None
        status = self.spec.field(self.spec.status_field)
        self._status_word = status.offset // 2
        self._go = self.spec.flag("go")
        self._sync = self.spec.flag("sync")
        self._prev_go: int | None = None
        self._prev_sync: int | None = None
        self.recording, self.baud = recording, baud
        from radar_io import __version__

        self.software = software or f"radar_io {__version__}"
        self.counts = Ch10Stats(events_skipped=skipped)
        self._names = {d.number: d.ident for d in self.defs}
        self._event_counts: dict[int, int] = {}
        self._seq: dict[int, int] = {}
        self._out: AtomicStream | None = None
        self._started = False
        self._origin_mono = 0
        self._offset = 0          # t_ns - mono_ns of the last chunk
        self._next_s = 0          # next whole wall-clock second to get a time packet
        self._last_mono = 0       # mono_ns of the last chunk
        self._uart: list[bytes] = []
        self._uart_bytes = 0
        self._uart_first: int | None = None   # mono_ns of the pending packet's first chunk
        self._uart_rtc = 0
        self._events: list[bytes] = []
        self._events_rtc = 0
        self._fe = 0              # next file event

    # ------------------------------------------------------------------ Sink
    def open(self) -> None:
        if self._out is None:
            self._out = AtomicStream(self.target)

    def write(self, batch: Batch) -> int:
        """Write a batch of received chunks (``t_ns``, ``mono_ns``, ``data`` columns)."""
        before = self.counts.bytes
        for t, m, d in zip(batch["t_ns"], batch["mono_ns"], batch["data"], strict=True):
            self.write_chunk(int(t), int(m), bytes(d))
        return self.counts.bytes - before

    def close(self) -> None:
        """Write what is pending and give the file its name (StorageError if the disk fails)."""
        out = self._out
        if out is None:
            return
        if not self._started:
            self.abort()
            raise RecordingError(f"{self.target}: no received chunks to write (empty recording)")
        try:
            while self._fe < len(self._file_events):  # events after the last chunk
                self._advance(self._file_mono(self._file_events[self._fe]))
            self._flush()
        except BaseException:
            self.abort()
            raise
        self._out = None
        out.close()

    def abort(self) -> None:
        """Drop the unfinished file; never raises."""
        out, self._out = self._out, None
        if out is not None:
            out.abort()

    def stats(self) -> dict[str, Any]:
        return self.counts.as_dict()

    # ------------------------------------------------------------------ chunks
    def rtc(self, mono_ns: int) -> int:
        """The 48-bit relative time counter (10 MHz) at a monotonic time."""
        return ((mono_ns - self._origin_mono) // RTC_TICK_NS) & RTC_MASK

    def write_chunk(self, t_ns: int, mono_ns: int, data: bytes) -> None:
        """Add one received chunk (wall and monotonic receive times, ns; its bytes)."""
        if self._out is None:
            self.open()
        if not self._started:
            self._start(t_ns, mono_ns)
        offset = t_ns - mono_ns
        if abs(offset - self._offset) > CLOCK_STEP_NS:
            # a wall-clock step: time packets on the old clock up to here, then one on the
            # new clock at the 10-ms boundary just before this chunk (just after it when
            # the previous chunk is later than that boundary: the RTC never runs back)
            at, label = mono_ns - t_ns % 10_000_000, t_ns - t_ns % 10_000_000
            if at < self._last_mono:
                at, label = at + 10_000_000, label + 10_000_000
            self._advance(at, inclusive=False)
            self._flush()
            self._offset = offset
            self._time_packet(at, label)
            self._next_s = label // 1_000_000_000 + 1
            self.counts.clock_steps += 1
            if self._derive_steps:
                self._add_event(CLOCK_STEP, mono_ns)
        self._offset = offset
        self._advance(mono_ns)
        if self._framer is not None:
            self._edges(data, mono_ns)
        self._uart_message(data, mono_ns)
        self._last_mono = mono_ns
        self.counts.chunks += 1

    def _start(self, t_ns: int, mono_ns: int) -> None:
        self._started = True
        self._offset = t_ns - mono_ns
        self._next_s = t_ns // 1_000_000_000
        first_time = self._next_s * 1_000_000_000 - self._offset
        self._origin_mono = first_time
        origin = dt.datetime.fromtimestamp(self._next_s, tz=dt.UTC)
        text = tmats_text(origin_utc=origin, recording=self.recording, baud=self.baud,
                          events=self.defs, software=self.software)
        self._file_events.sort(key=self._file_mono)
        self._emit(CHANNEL_COMPUTER, DT_TMATS, self.rtc(first_time),
                   struct.pack("<I", TMATS_VERSION) + text.encode("ascii"))

    def _file_mono(self, e: FileEvent) -> int:
        """An event-log event's monotonic time (from ``t_ns`` on the current clock offset if
        it has none); one before the first time packet is placed on it."""
        mono = e.mono_ns if e.mono_ns is not None else (e.t_ns or 0) - self._offset
        return max(mono, self._origin_mono)

    def _advance(self, mono_ns: int, inclusive: bool = True) -> None:
        """Time packets and event-log events due up to ``mono_ns``, in time order."""
        while True:
            t_next = self._next_s * 1_000_000_000 - self._offset
            ev = self._file_events[self._fe] if self._fe < len(self._file_events) else None
            e_next = self._file_mono(ev) if ev is not None else None
            due_t = t_next < mono_ns or (inclusive and t_next == mono_ns)
            due_e = e_next is not None and (e_next < mono_ns or (inclusive and e_next == mono_ns))
            if due_t and (not due_e or t_next <= e_next):  # type: ignore[operator]
                self._flush()
                self._time_packet(t_next, self._next_s * 1_000_000_000)
                self._next_s += 1
            elif due_e and ev is not None and e_next is not None:
                self._add_event(ev.number, e_next)
                self._fe += 1
            else:
                return

    def _time_packet(self, mono_ns: int, t_ns: int) -> None:
        self._emit(CHANNEL_TIME, DT_TIME_F1, self.rtc(mono_ns), time_body(t_ns))
        self.counts.time_packets += 1

    def _edges(self, data: bytes, mono_ns: int) -> None:
        assert self._framer is not None
        frames = self._framer.feed(data)
        if not frames.shape[0]:
            return
        sts = frames[:, self._status_word]
        for flag, prev_attr, rise, fall in ((self._go, "_prev_go", GO_ON, GO_OFF),
                                            (self._sync, "_prev_sync", SYNC_ON, None)):
            v = (sts & flag.mask) >> flag.shift
            prev = getattr(self, prev_attr)
            seq = v if prev is None else np.concatenate(([prev], v))
            d = np.diff(seq.astype(np.int8))
            for step in d[d != 0]:
                if step > 0:
                    self._add_event(rise, mono_ns)
                elif fall is not None:
                    self._add_event(fall, mono_ns)
            setattr(self, prev_attr, int(v[-1]))

    def _add_event(self, number: int, mono_ns: int) -> None:
        if len(self._events) >= MAX_EVENTS_PER_PACKET:
            self._flush()
        count = self._event_counts.get(number, 0) + 1
        self._event_counts[number] = count
        rtc = self.rtc(mono_ns)
        if not self._events:
            self._events_rtc = rtc
        # entry: event number bits 11-0, count bits 27-12, occurred while recording bit 28
        self._events.append(_EVENT.pack(rtc, (number & 0xFFF) | ((count & 0xFFFF) << 12)
                                        | (1 << 28)))
        name = self._names.get(number, str(number))
        self.counts.events[name] = self.counts.events.get(name, 0) + 1

    def _uart_message(self, data: bytes, mono_ns: int) -> None:
        if self._uart_first is not None and mono_ns - self._uart_first >= UART_PACKET_SPAN_NS:
            self._flush()
        rtc = self.rtc(mono_ns)
        room_max = MAX_PACKET_BYTES - 24 - 4 - 4 - 3   # header, CSDW, checksum, filler
        view = memoryview(data)
        while True:
            piece = view[:MAX_UART_MESSAGE_BYTES]
            size = _IPH_UART.size + len(piece) + (len(piece) & 1)
            if self._uart_bytes + size > room_max:
                self._flush()
            if not self._uart:
                self._uart_first, self._uart_rtc = mono_ns, rtc
            # intra-packet data header: length bits 15-0, subchannel bits 29-16 (0), parity bit 31
            self._uart.append(_IPH_UART.pack(rtc, len(piece)))
            self._uart.append(bytes(piece) + (b"\0" if len(piece) & 1 else b""))
            self._uart_bytes += size
            self.counts.uart_messages += 1
            self.counts.uart_bytes += len(piece)
            view = view[len(piece):]
            if not view:
                return

    def _flush(self) -> None:
        """Write the pending event and UART packets."""
        if self._events:
            body = struct.pack("<I", len(self._events)) + b"".join(self._events)
            self._emit(CHANNEL_COMPUTER, DT_EVENT, self._events_rtc, body)
            self.counts.event_packets += 1
            self._events = []
        if self._uart:
            body = struct.pack("<I", 1 << 31) + b"".join(self._uart)  # CSDW: IPH present
            self._emit(CHANNEL_UART, DT_UART_F0, self._uart_rtc, body)
            self.counts.uart_packets += 1
            self._uart, self._uart_bytes, self._uart_first = [], 0, None

    def _emit(self, channel: int, data_type: int, rtc: int, body: bytes) -> None:
        seq = self._seq.get(channel, 0)
        self._seq[channel] = (seq + 1) & 0xFF
        pkt = encode_packet(channel, data_type, seq, rtc, body)
        assert self._out is not None
        self._out.write(pkt)
        self.counts.packets += 1
        self.counts.bytes += len(pkt)


def baud_of(source: str) -> int | None:
    """The baud rate named in a recording header's source URL (``…baudrate=N``), if any."""
    m = re.search(r"baudrate=(\d+)", source or "")
    return int(m.group(1)) if m else None


def events_path_for(recording: str | os.PathLike[str]) -> Path:
    """``REC.events.jsonl`` beside ``REC.rdrlog``."""
    return Path(recording).with_suffix(".events.jsonl")


def export_recording(src: str | os.PathLike[str], dst: str | os.PathLike[str], *,
                     events_path: str | os.PathLike[str] | None = None, spec: Any = None,
                     progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Export a ``.rdrlog`` to a Chapter 10 file (temporary name, renamed when complete).

    Returns the writer's counters plus the recording's read problems."""
    from radar_io.recording.rdrlog import RecordingReader, is_recording

    if not os.path.exists(src):
        raise RecordingError(f"input not found: {src}")
    if not is_recording(src):
        raise RecordingError(f"{src}: a Chapter 10 export needs a .rdrlog recording "
                             "(its chunks' receive times), not a raw capture")
    ev_path = Path(events_path) if events_path is not None else events_path_for(src)
    if events_path is not None and not ev_path.is_file():
        raise RecordingError(f"event log not found: {ev_path}")
    records = read_events_file(ev_path)
    with RecordingReader(src) as reader:
        writer = Ch10Writer(dst, spec=spec, events=records, recording=Path(src).name,
                            baud=baud_of(str(reader.header.get("source", ""))))
        writer.open()
        try:
            for n, c in enumerate(reader, 1):
                writer.write_chunk(c.t_ns, c.mono_ns, c.data)
                if progress is not None and n % 4096 == 0:
                    progress(c.offset, reader.size)
            writer.close()
        except BaseException:
            writer.abort()
            raise
        if progress is not None:
            progress(reader.size, reader.size)
        out = writer.counts.as_dict()
        out["problems"] = list(reader.report.problems)
        out["events_file"] = str(ev_path) if records else None
    return out
