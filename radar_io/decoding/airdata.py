"""The airborne recorder's CAN layout (``firmware_specs/airdata.dbc``) and decoding CAN logs with it.

Messages (see the DBC's comments and docs/guidance-telemetry-can.md):

* ``SHUTTER_EVENT`` — one per camera-shutter closure: event number and the
  aircraft (DAU) clock time of the closure in 0.1 ms units;
* ``AIR_DATA_TIME`` then ``AIR_DATA_1``, ``ATTITUDE``, ``DME`` — one 8 Hz
  air data sample, tied together by ``SampleCount``; ``AIR_DATA_TIME`` carries
  the DAU-clock sample time and the latched shutter counter.

Decoding uses cantools; logs are read with python-can's ``LogReader`` (format
from the file extension: .asc, .blf, .log, .csv, .trc, ...).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from radar_io.errors import AirborneError
from radar_io.textfiles import decode_text, one_line, read_text
from radar_io.wirespec.frame import spec_dir

#: message name → the signals radar_io relies on
REQUIRED = {
    "SHUTTER_EVENT": ("ShutterCount", "ShutterTime"),
    "AIR_DATA_TIME": ("SampleCount", "SampleTime", "ShutterCountLatched"),
    "AIR_DATA_1": ("SampleCount", "IAS", "PressureAltitude"),
    "ATTITUDE": ("SampleCount", "Pitch", "Roll", "Heading"),
    "DME": ("SampleCount", "DME1Range", "DME2Range"),
}
#: 8 Hz sample signal → column of :attr:`AircraftLog.samples`
SAMPLE_COLUMNS = {
    "SampleTime": "time_s", "ShutterCountLatched": "shutter_count", "IAS": "ias_kt",
    "PressureAltitude": "pressure_altitude_ft", "Pitch": "pitch_deg", "Roll": "roll_deg",
    "Heading": "heading_deg", "DME1Range": "dme1_nm", "DME2Range": "dme2_nm",
}


def load_dbc(path: str | os.PathLike[str] | None = None) -> Any:
    """The cantools database of ``firmware_specs/airdata.dbc`` (or ``path``), checked for the
    signals used."""
    import cantools

    p = Path(path) if path is not None else spec_dir() / "airdata.dbc"
    text = decode_text(*read_text(p, "DBC file", AirborneError), "DBC file", AirborneError,
                       allow_empty=False)
    try:
        db = cantools.database.load_string(text, database_format="dbc")
    except Exception as exc:  # cantools raises many parse error types
        raise AirborneError(one_line(f"DBC file {p} cannot be parsed: {exc}")) from exc
    if not isinstance(db, cantools.database.can.Database):
        raise AirborneError(f"DBC file {p}: not a CAN database")
    for name, signals in REQUIRED.items():
        try:
            msg = db.get_message_by_name(name)
        except KeyError as exc:
            raise AirborneError(f"DBC file {p}: message {name}: missing") from exc
        missing = [s for s in signals if s not in {x.name for x in msg.signals}]
        if missing:
            raise AirborneError(f"DBC file {p}: message {name}: missing signal(s) {', '.join(missing)}")
        if msg.is_extended_frame:
            raise AirborneError(f"DBC file {p}: message {name}: must use a standard (11-bit) identifier")
    return db


@dataclass
class AircraftLog:
    """Decoded recorder traffic: shutter events and 8 Hz samples (aircraft clock, s)."""

    event_count: np.ndarray          #: ShutterCount of each SHUTTER_EVENT, log order
    event_time_s: np.ndarray         #: ShutterTime (aircraft clock)
    samples: dict[str, np.ndarray]   #: SAMPLE_COLUMNS + sample_count; NaN where a part is missing
    messages: int = 0
    unknown: int = 0                 #: messages with an identifier not in the DBC
    undecodable: int = 0             #: wrong length / malformed payloads
    problems: list[str] = field(default_factory=list)


class AirDataDecoder:
    """Decodes python-can messages one at a time (live use; :func:`decode_messages` for logs).

    :meth:`feed` returns ``("event", (count, time_s))`` for a shutter event,
    ``("sample_start", row)`` for the first message of an 8 Hz sample (its time),
    ``("sample", row)`` for each further part, or None. ``row`` is that sample's
    dict of :data:`SAMPLE_COLUMNS`, filled in place as its parts arrive.
    """

    def __init__(self, db: Any) -> None:
        self.db = db
        self.ids = {db.get_message_by_name(n).frame_id: n for n in REQUIRED}
        self.latest: dict[int, dict[str, float]] = {}   # SampleCount → its most recent row
        self.messages = self.unknown = self.undecodable = 0

    def feed(self, m: Any) -> tuple[str, Any] | None:
        if m.is_error_frame or m.is_remote_frame:
            return None
        self.messages += 1
        name = None if m.is_extended_id else self.ids.get(m.arbitration_id)
        if name is None:
            self.unknown += 1
            return None
        try:
            sig = self.db.decode_message(m.arbitration_id, bytes(m.data), decode_choices=False)
        except Exception:  # noqa: BLE001 - a malformed payload is counted, never fatal
            self.undecodable += 1
            return None
        if name == "SHUTTER_EVENT":
            return "event", (int(sig["ShutterCount"]), float(sig["ShutterTime"]))
        count = int(sig["SampleCount"])
        kind = "sample"
        if name == "AIR_DATA_TIME":
            row = {"sample_count": float(count)}
            self.latest[count] = row
            if len(self.latest) > 64:  # keep the recent samples only
                del self.latest[next(iter(self.latest))]
            kind = "sample_start"
        else:
            started = self.latest.get(count)
            if started is None:  # its AIR_DATA_TIME was lost: the sample has no time
                self.undecodable += 1
                return None
            row = started
        for s, col in SAMPLE_COLUMNS.items():
            if s in sig:
                row[col] = float(sig[s])
        return kind, row


def decode_messages(msgs: Iterable[Any], db: Any) -> AircraftLog:
    """Decode python-can messages (log order) into an :class:`AircraftLog`."""
    dec = AirDataDecoder(db)
    events: list[tuple[int, float]] = []
    rows: list[dict[str, float]] = []
    for m in msgs:
        got = dec.feed(m)
        if got is None:
            continue
        kind, value = got
        if kind == "event":
            events.append(value)
        elif kind == "sample_start":
            rows.append(value)
    samples = {c: np.array([r.get(c, np.nan) for r in rows], dtype=np.float64)
               for c in ("sample_count", *SAMPLE_COLUMNS.values())}
    ev = np.array(events, dtype=np.float64).reshape(-1, 2)
    return AircraftLog(event_count=ev[:, 0].astype(np.int64), event_time_s=ev[:, 1],
                       samples=samples, messages=dec.messages, unknown=dec.unknown,
                       undecodable=dec.undecodable)


def read_can_log(path: str | os.PathLike[str], db: Any = None) -> AircraftLog:
    """Read a python-can log file (format by extension) and decode it with the DBC."""
    import can

    db = db if db is not None else load_dbc()
    p = Path(path)
    if not p.is_file():
        raise AirborneError(f"CAN log not found: {p}")
    try:
        with can.LogReader(str(p)) as reader:
            return decode_messages(reader, db)
    except AirborneError:
        raise
    except Exception as exc:  # python-can readers raise many types on bad files
        raise AirborneError(f"cannot read CAN log {p}: {exc}") from exc
