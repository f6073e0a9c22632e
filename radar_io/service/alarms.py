"""Limit alarms: configured limits on decoded columns plus built-in health alarms.

Pure engine (no web, no threads of its own). Two clocks: every duration (``for_s``, the
CRC-rate window, the wait for the first frame, ``duration_s``) is measured on a monotonic
clock (``mono_s`` of :meth:`AlarmEngine.feed` / :meth:`AlarmEngine.check_status`, the
service passes ``time.monotonic()``), so a wall-clock step neither raises, clears nor
delays an alarm; ``since`` / ``t_s`` are wall-clock labels (s since the Unix epoch).

* **Limit alarms** come from the config's ``[[alarms]]`` entries::

      [[alarms]]
      column = "dz_m"      # any decoded column
      min = -30.0          # optional lower limit (column's unit)
      max = 30.0           # optional upper limit
      for_s = 0.5          # out of limits this long (monotonic receive time) before raising
      name = "glide path"  # optional; id defaults to "limit:<column>"

  :meth:`AlarmEngine.feed` takes the decoded messages (dicts with ``t_ns`` and ``seq``).
  A sample outside [min, max] starts the clock; the alarm is raised when every sample
  for ``for_s`` has been outside, and cleared by the first sample back inside. Empty
  (None / NaN, e.g. NG) samples neither start nor clear an alarm.
* **Built-in alarms** are checked from the service status dict by
  :meth:`AlarmEngine.check_status`: ``source_stale`` (no frame for ``stale_s``),
  ``crc_rate`` (CRC errors per second over ``crc_window_s``), ``recording_error``,
  ``uplink`` (a TLM / D/A sink not connected), ``low_disk`` (free bytes in the data
  directory) and ``calibration_unreadable`` (``active.json`` could not be read at start).
  Their limits can be changed or switched off with config entries
  ``{builtin = "crc_rate", max = 5.0}`` / ``{builtin = "low_disk", enabled = false}``.

Each active alarm is ``{id, name, column, value, limit, since, acknowledged}`` (``since``:
raise time, s since the epoch). Every raise, clear and acknowledge calls ``on_event(record)``
(the record carries the radar SEQ and both times, ``t_ns`` and ``mono_ns``, for the
recording's events) and every change of the active list calls ``on_change(alarms)`` (for
the websocket).
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from radar_io.errors import ConfigError, NotFoundError

#: built-in alarm → (column shown, default limit, limit kind)
BUILTINS: dict[str, tuple[str, float, str]] = {
    "source_stale": ("last_frame_age_s", 1.0, "max"),
    "crc_rate": ("crc_errors_per_s", 1.0, "max"),
    "recording_error": ("recording_error", 0.0, "flag"),
    "uplink": ("uplink_connected", 0.0, "flag"),
    "low_disk": ("disk_free_bytes", 1e9, "min"),
    "calibration_unreadable": ("calibration_error", 0.0, "flag"),
}
BUILTIN_NAMES = {
    "source_stale": "source stale", "crc_rate": "CRC error rate",
    "recording_error": "recording error", "uplink": "uplink disconnected",
    "low_disk": "low disk space", "calibration_unreadable": "calibration set unreadable",
}
_RULE_KEYS = {"id", "name", "column", "min", "max", "for_s", "builtin", "enabled"}


@dataclass(frozen=True)
class LimitRule:
    """One ``[[alarms]]`` limit on a decoded column (limits in the column's unit)."""

    id: str
    name: str
    column: str
    min: float | None
    max: float | None
    for_s: float = 0.0


def _num(entry: dict[str, Any], key: str, where: str) -> float | None:
    v = entry.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{where}: {key} must be a finite number, got {v!r}")
    return float(v)


def parse_alarm_config(entries: Iterable[dict[str, Any]], source: str = "config",
                       columns: Iterable[str] | None = None
                       ) -> tuple[list[LimitRule], dict[str, float | None]]:
    """Limit rules and built-in limits (None = switched off) from ``[[alarms]]`` entries."""
    known = set(columns) if columns is not None else None
    rules: list[LimitRule] = []
    builtin: dict[str, float | None] = {k: v[1] for k, v in BUILTINS.items()}
    ids: set[str] = set()
    for k, e in enumerate(entries):
        where = f"{source}: alarms[{k}]"
        if not isinstance(e, dict):
            raise ConfigError(f"{where}: expected a table, got {type(e).__name__}")
        extra = set(e) - _RULE_KEYS
        if extra:
            raise ConfigError(f"{where}: unknown key(s) {', '.join(sorted(extra))}")
        enabled = e.get("enabled", True)
        if not isinstance(enabled, bool):
            raise ConfigError(f"{where}: enabled must be true or false")
        if "builtin" in e:
            b = e["builtin"]
            if b not in BUILTINS:
                raise ConfigError(f"{where}: builtin {b!r} is not one of {', '.join(BUILTINS)}")
            kind = BUILTINS[b][2]
            lim = _num(e, kind, where) if kind in ("min", "max") else None
            builtin[b] = None if not enabled else (lim if lim is not None else BUILTINS[b][1])
            continue
        col = e.get("column")
        if not isinstance(col, str) or not col:
            raise ConfigError(f"{where}: column (a decoded column name) is required")
        if known is not None and col not in known:
            raise ConfigError(f"{where}: column {col!r} is not a decoded column "
                              f"({', '.join(sorted(known))})")
        lo, hi = _num(e, "min", where), _num(e, "max", where)
        if lo is None and hi is None:
            raise ConfigError(f"{where}: give min, max or both")
        if lo is not None and hi is not None and lo > hi:
            raise ConfigError(f"{where}: min {lo} is above max {hi}")
        for_s = _num(e, "for_s", where) or 0.0
        if for_s < 0:
            raise ConfigError(f"{where}: for_s must be >= 0")
        rid = str(e.get("id") or f"limit:{col}")
        if rid in ids:
            raise ConfigError(f"{where}: duplicate alarm id {rid!r} (give each an id)")
        ids.add(rid)
        if enabled:
            rules.append(LimitRule(rid, str(e.get("name") or f"{col} out of limits"), col,
                                   lo, hi, for_s))
    return rules, builtin


def _iso(t_s: float) -> str:
    """UTC ISO 8601 with milliseconds (rounded to the nearest ms)."""
    sec, ms = divmod(round(t_s * 1000), 1000)
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(sec)) + f".{ms:03d}Z"


class AlarmEngine:
    """Raises and clears alarms; see the module docstring. Thread-safe."""

    def __init__(self, rules: Iterable[LimitRule] = (),
                 builtin: dict[str, float | None] | None = None, *,
                 crc_window_s: float = 10.0,
                 on_change: Callable[[list[dict[str, Any]]], None] | None = None,
                 on_event: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.rules = list(rules)
        self.builtin = dict(builtin) if builtin is not None else {k: v[1] for k, v in BUILTINS.items()}
        self.crc_window_s = crc_window_s
        self.on_change, self.on_event = on_change, on_event
        self._lock = threading.RLock()
        self._active: dict[str, dict[str, Any]] = {}
        self._out_since: dict[str, float] = {}      # rule id → first out-of-limit time (mono)
        self._raised_mono: dict[str, float] = {}    # alarm id → raise time (mono)
        self._crc: deque[tuple[float, int]] = deque()
        self.last_seq: int | None = None
        self._first_check: float | None = None
        self.events: deque[dict[str, Any]] = deque(maxlen=1000)  #: recent raise/clear/ack records

    # ------------------------------------------------------------------ inputs
    def feed(self, msgs: list[dict[str, Any]], mono_s: float | None = None) -> None:
        """Decoded messages, oldest first (``t_ns`` wall-clock receive time, ``seq`` radar
        SEQ), received at monotonic time ``mono_s`` (s; default: each message's ``t_ns``, for
        a stream with its own times)."""
        if not msgs:
            return
        with self._lock:
            changed = False
            for rule in self.rules:
                for m in msgs:
                    v = m.get(rule.column)
                    if v is None or (isinstance(v, float) and math.isnan(v)):
                        continue
                    t = m["t_ns"] / 1e9 if m.get("t_ns") else time.time()  # a label
                    changed |= self._judge(rule.id, rule.name, rule.column, float(v), t,
                                           t if mono_s is None else mono_s,
                                           lo=rule.min, hi=rule.max, for_s=rule.for_s, m=m)
            last = msgs[-1]
            self.last_seq = last.get("seq", self.last_seq)
            if changed:
                self._changed()

    def check_status(self, status: dict[str, Any], now_s: float | None = None,
                     mono_s: float | None = None) -> None:
        """Built-in alarms from the service status dict (see
        :meth:`~radar_io.service.state.ServiceState.status`) and ``disk_free_bytes``;
        ``now_s``: wall clock (a label), ``mono_s``: monotonic clock for the CRC window and
        waits (default ``time.monotonic()``, or ``now_s`` when only that is given)."""
        now = time.time() if now_s is None else now_s  # a label
        mono = mono_s if mono_s is not None else (time.monotonic() if now_s is None else now_s)
        with self._lock:
            changed = False
            lim = self.builtin
            if lim.get("source_stale") is not None:
                age = status.get("last_frame_age_s")
                if status.get("mode", "live") == "live" and "last_frame_age_s" in status:
                    if self._first_check is None:
                        self._first_check = mono
                    # no frame yet: stale once the engine has waited stale_s for the first
                    val = float(age) if age is not None else mono - self._first_check
                    changed |= self._judge("source_stale", BUILTIN_NAMES["source_stale"],
                                           "last_frame_age_s", val, now, mono,
                                           hi=lim["source_stale"])
            if lim.get("crc_rate") is not None and status.get("crc_errors") is not None:
                q = self._crc
                q.append((mono, int(status["crc_errors"])))
                while len(q) > 2 and mono - q[1][0] >= self.crc_window_s:
                    q.popleft()
                dt = q[-1][0] - q[0][0]
                rate = (q[-1][1] - q[0][1]) / dt if dt > 0 else 0.0
                changed |= self._judge("crc_rate", BUILTIN_NAMES["crc_rate"], "crc_errors_per_s",
                                       max(rate, 0.0), now, mono, hi=lim["crc_rate"])
            if lim.get("recording_error") is not None:
                err = status.get("recording_error")
                changed |= self._flag("recording_error", "recording_error", err, now, mono)
            if lim.get("uplink") is not None:
                down = [k for k, s in (status.get("uplink") or {}).items()
                        if isinstance(s, dict) and not s.get("connected", True)]
                changed |= self._flag("uplink", "uplink_connected",
                                      ", ".join(down) + " not connected" if down else None,
                                      now, mono)
            if lim.get("calibration_unreadable") is not None:
                changed |= self._flag("calibration_unreadable", "calibration_error",
                                      status.get("calibration_error"), now, mono)
            if lim.get("low_disk") is not None and status.get("disk_free_bytes") is not None:
                changed |= self._judge("low_disk", BUILTIN_NAMES["low_disk"], "disk_free_bytes",
                                       float(status["disk_free_bytes"]), now, mono,
                                       lo=lim["low_disk"])
            if changed:
                self._changed()

    # ------------------------------------------------------------------ outputs
    def active(self) -> list[dict[str, Any]]:
        """Active alarms, oldest first (copies)."""
        with self._lock:
            return [dict(a) for a in sorted(self._active.values(), key=lambda a: a["since"])]

    def snapshot(self, now_s: float | None = None) -> None:
        """One ``active`` event per active alarm (written when a new recording opens, so
        its event log starts with the alarms already standing)."""
        t = time.time() if now_s is None else now_s  # a label
        with self._lock:
            for a in self.active():
                self._event("active", a, t, time.monotonic(), {"since": a["since"]})

    def acknowledge(self, alarm_id: str, by: str = "operator") -> dict[str, Any]:
        """Mark an active alarm acknowledged (it stays active until it clears)."""
        with self._lock:
            a = self._active.get(alarm_id)
            if a is None:
                raise NotFoundError(f"no active alarm {alarm_id!r}")
            if not a["acknowledged"]:
                a["acknowledged"] = True
                self._event("ack", a, time.time(), time.monotonic(), {"by": by})  # label, clock
                self._changed()
            return dict(a)

    # ------------------------------------------------------------------ internals
    def _judge(self, aid: str, name: str, column: str, value: float, t: float, mono: float, *,
               lo: float | None = None, hi: float | None = None, for_s: float = 0.0,
               m: dict[str, Any] | None = None) -> bool:
        """Update one limit alarm with one value at wall time ``t`` (label) and monotonic
        time ``mono`` (s); True when raised or cleared."""
        limit = None
        if hi is not None and value > hi:
            limit = hi
        elif lo is not None and value < lo:
            limit = lo
        a = self._active.get(aid)
        if limit is None:
            self._out_since.pop(aid, None)
            if a is not None:
                a["value"] = value
                self._clear(aid, t, mono, m)
                return True
            return False
        t0 = self._out_since.setdefault(aid, mono)
        if a is not None:
            a["value"] = value
            return False
        if mono - t0 >= for_s:
            self._raise(aid, name, column, value, limit, t, mono, m)
            return True
        return False

    def _flag(self, aid: str, column: str, problem: Any, now: float,
              mono: float | None = None) -> bool:
        """A built-in alarm raised while ``problem`` is set (``mono``: monotonic s, default
        now)."""
        mono = time.monotonic() if mono is None else mono
        a = self._active.get(aid)
        if problem:
            if a is None:
                self._raise(aid, BUILTIN_NAMES[aid], column, str(problem), None, now, mono, None)
                return True
            a["value"] = str(problem)
            return False
        if a is not None:
            self._clear(aid, now, mono, None)
            return True
        return False

    def _raise(self, aid: str, name: str, column: str, value: Any, limit: float | None,
               t: float, mono: float, m: dict[str, Any] | None) -> None:
        a = {"id": aid, "name": name, "column": column, "value": value, "limit": limit,
             "since": t, "since_utc": _iso(t), "acknowledged": False}
        self._active[aid] = a
        self._raised_mono[aid] = mono
        self._event("raise", a, t, mono, {}, m)

    def _clear(self, aid: str, t: float, mono: float, m: dict[str, Any] | None) -> None:
        a = self._active.pop(aid)
        duration = mono - self._raised_mono.pop(aid, mono)
        self._event("clear", a, t, mono, {"duration_s": duration}, m)

    def _event(self, action: str, a: dict[str, Any], t: float, mono: float,
               extra: dict[str, Any], m: dict[str, Any] | None = None) -> None:
        rec = {"type": "alarm", "action": action, "id": a["id"], "name": a["name"],
               "column": a["column"], "value": a["value"], "limit": a["limit"],
               "seq": m.get("seq") if m else self.last_seq,
               "t_s": t, "time_utc": _iso(t), "t_ns": round(t * 1e9),
               "mono_ns": round(mono * 1e9), **extra}
        self.events.append(rec)
        if self.on_event is not None:
            self.on_event(rec)

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change(self.active())


def _clean(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def alarm_message(alarms: list[dict[str, Any]]) -> str:
    """The websocket message: ``{"type": "alarm", "alarms": [...]}`` (inf/NaN → null)."""
    return json.dumps({"type": "alarm", "alarms": [{k: _clean(v) for k, v in a.items()}
                                                   for a in alarms]}, allow_nan=False)


class EventLog:
    """Alarm records into the open recording's events ``<id>.events.jsonl`` (kind ``alarm``,
    written by the recorder's writer thread: the caller, often the reader thread, never
    touches the disk); a record with no recording open is kept in memory only
    (:attr:`AlarmEngine.events`)."""

    def __init__(self, recorder: Any) -> None:
        self.recorder = recorder

    def __call__(self, record: dict[str, Any]) -> None:
        fields = {k: _clean(v) for k, v in record.items() if k not in ("t_ns", "mono_ns")}
        self.recorder.event("alarm", {**fields, "recording": self.recorder.current},
                            t_ns=record["t_ns"], mono_ns=record["mono_ns"])


def read_events(path: Path) -> list[dict[str, Any]]:
    """The records of an ``.events.jsonl`` file (missing file: none; bad lines skipped)."""
    out = []
    try:
        with open(path, encoding="utf-8") as f:
            for line in f:
                try:
                    out.append(json.loads(line))
                except json.JSONDecodeError:
                    continue
    except FileNotFoundError:
        return []
    return out


# ---------------------------------------------------------------------- service glue
def attach_alarms(svc: Any) -> AlarmEngine:
    """An engine for a :class:`~radar_io.service.state.ServiceState`: rules from ``cfg.alarms``,
    fed the decoded messages (an acquisition processor), events to the open recording's
    event log, changes pushed on the websocket (coalesced per client: a flapping limit
    costs a client one waiting message). Start :func:`status_loop` in the lifespan."""
    from radar_io.coordinates.reference_path import DEVIATION_COLUMNS
    from radar_io.decoding.model import output_columns

    columns = [*output_columns(svc.spec, svc.site), "t_ns"]
    if getattr(svc, "path", None) is not None:
        columns += DEVIATION_COLUMNS
    entries = getattr(svc.cfg, "alarms", None) or []
    rules, builtin = parse_alarm_config(entries, "config", columns)
    low_mb = getattr(svc.cfg, "low_space_mb", None)
    if low_mb is not None and builtin.get("low_disk") is not None and \
            not any(e.get("builtin") == "low_disk" for e in entries):
        builtin["low_disk"] = float(low_mb) * (1 << 20)  # the status's low_space threshold
    publish = getattr(svc.hub, "publish_event_threadsafe", None)

    def on_change(alarms: list[dict[str, Any]]) -> None:
        if publish is not None:
            publish(alarm_message(alarms))

    engine = AlarmEngine(rules, builtin, on_change=on_change, on_event=EventLog(svc.recorder))

    def feed(msgs: list[dict[str, Any]]) -> None:  # durations on the monotonic clock
        engine.feed(msgs, mono_s=time.monotonic())

    svc.live.processors.append(feed)  # the live pipeline only: never a replay
    return engine


def service_status(svc: Any) -> dict[str, Any]:
    """The status dict plus ``disk_free_bytes`` of the data directory."""
    import shutil

    st = svc.status()
    try:
        st["disk_free_bytes"] = shutil.disk_usage(svc.data_dir).free
    except OSError:
        st["disk_free_bytes"] = 0
    return st


async def status_loop(svc: Any, engine: AlarmEngine, period_s: float = 0.25) -> None:
    """Check the built-in alarms every ``period_s`` until cancelled."""
    import asyncio
    import logging

    recording = None
    while True:
        try:
            engine.check_status(service_status(svc))
            current = svc.recorder.current
            if current is not None and current != recording:
                engine.snapshot()
            recording = current
        except Exception:  # a failing check must not end the loop
            logging.getLogger("radar_io.alarms").exception("alarm status check failed")
        await asyncio.sleep(period_s)
