"""MQTT publishing (paho-mqtt): the live track, the service status and sync events.

``mqtt://HOST:PORT/PREFIX[?qos=0|1]`` (``mqtts://`` for TLS, default ports 1883 / 8883).
Topics:

* ``PREFIX/track`` — JSON arrays of the ``/ws/live`` messages (each with ``msg_seq``),
  one array per ≤ ``batch_s`` (100 ms);
* ``PREFIX/status`` — ``{"online": true, …/api/status…}`` every ``status_period_s``
  (1 s), retained; the last will (and a clean close) is ``{"online": false}``, retained;
* ``PREFIX/sync`` — one JSON object per sync event (SYNC 0→1 edge).

:class:`MqttPublisher` never blocks its caller (the acquisition thread): ``submit``
appends to a bounded deque (no lock, no wake-up of another thread: the publisher
thread collects every ``batch_s``) and counts what does not fit; what arrives while
the broker is away is dropped and counted (``dropped``), never queued without bound.
paho's network thread reconnects with back-off (0.1 s doubling to 2 s, so a broker
back after a restart is used again within ~2 s). User and password come from the
arguments (the config) or ``RADAR_IO_MQTT_USER`` / ``RADAR_IO_MQTT_PASSWORD``; they
are never put in a URL, a log line or the stats.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
import urllib.parse
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from radar_io.errors import ConfigError, UplinkError
from radar_io.sinks.base import Batch, Sink
from radar_io.textfiles import json_safe

log = logging.getLogger("radar_io.sinks.mqtt")

USER_ENV = "RADAR_IO_MQTT_USER"
PASSWORD_ENV = "RADAR_IO_MQTT_PASSWORD"
RECONNECT_MIN_S = 0.1
RECONNECT_MAX_S = 2.0
OFFLINE = json.dumps({"online": False})


@dataclass(frozen=True)
class MqttTarget:
    """A parsed ``mqtt://`` / ``mqtts://`` URL."""

    host: str
    port: int
    prefix: str
    qos: int
    tls: bool

    def topic(self, name: str) -> str:
        return f"{self.prefix}/{name}" if self.prefix else name

    def __str__(self) -> str:
        scheme = "mqtts" if self.tls else "mqtt"
        return f"{scheme}://{self.host}:{self.port}/{self.prefix}?qos={self.qos}"


def parse_mqtt_url(url: str) -> MqttTarget:
    """``mqtt[s]://HOST[:PORT]/PREFIX[?qos=0|1]``; ConfigError names what is wrong."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts"):
        raise ConfigError(f"{url}: expected mqtt://HOST:PORT/PREFIX or mqtts://…")
    if parts.username is not None or parts.password is not None:
        raise ConfigError(f"{parts.scheme}://{parts.hostname}…: put the MQTT user and password "
                          f"in the config or {USER_ENV}/{PASSWORD_ENV}, not in the URL")
    try:
        port = parts.port
    except ValueError as exc:
        raise ConfigError(f"{url}: port must be 1 .. 65535") from exc
    if not parts.hostname:
        raise ConfigError(f"{url}: no broker host")
    prefix = parts.path.strip("/")
    if any(c in prefix for c in "+#\0") or "#" in url:
        raise ConfigError(f"{url}: the topic prefix {prefix!r} must not hold +, # or NUL")
    q = urllib.parse.parse_qs(parts.query)
    unknown = set(q) - {"qos"}
    if unknown:
        raise ConfigError(f"{url}: unknown option(s) {', '.join(sorted(unknown))} (known: qos)")
    qos_text = q.get("qos", ["1"])[-1]
    if qos_text not in ("0", "1"):
        raise ConfigError(f"{url}: qos = {qos_text!r} must be 0 or 1")
    tls = parts.scheme == "mqtts"
    return MqttTarget(parts.hostname, port or (8883 if tls else 1883), prefix, int(qos_text), tls)


def _json(doc: Any) -> str:
    """Strict JSON (non-finite floats → null)."""
    return json.dumps(json_safe(doc), separators=(",", ":"), default=str)


class MqttPublisher:
    """Publishes to one broker from its own thread; see the module docstring.

    ``status``: returns the ``/api/status`` document (called on the publisher thread once
    per ``status_period_s``); ``sync_events``: returns the recent sync events (objects with
    ``as_dict()`` or dicts, each with a ``msg_seq``), polled every batch period; each is
    published once.
    """

    def __init__(self, url: str, *, status: Callable[[], dict[str, Any]] | None = None,
                 sync_events: Callable[[], list[Any]] | None = None,
                 username: str | None = None, password: str | None = None,
                 ca_file: str | None = None, client_id: str = "",
                 batch_s: float = 0.1, status_period_s: float = 1.0,
                 max_queue: int = 2000, max_batch_messages: int = 2000) -> None:
        self.target = parse_mqtt_url(url)
        self.url = str(self.target)  # no credentials, ever
        if not 0 < batch_s <= 1.0 or not status_period_s > 0:
            raise ConfigError("mqtt: batch_s must be in (0, 1] s and status_period_s > 0")
        self._username = username if username is not None else os.environ.get(USER_ENV)
        self._password = password if password is not None else os.environ.get(PASSWORD_ENV)
        if ca_file is not None and not os.path.isfile(ca_file):
            raise ConfigError(f"{self.url}: CA file {ca_file} not found")
        self._ca_file, self._client_id = ca_file, client_id
        self.batch_s, self.status_period_s = batch_s, status_period_s
        self.max_batch_messages = max_batch_messages
        self._status_fn, self._sync_fn = status, sync_events
        self._q: deque[list[tuple[int, str]]] = deque()
        self.max_queue = max_queue
        # never held while calling paho: paho calls on_publish under its own message lock
        self._lock = threading.Lock()
        self._pending: dict[int, int] = {}   # mid → track messages in that payload
        self._early: set[int] = set()        # mids acknowledged before they were registered
        self.connected = False
        self.published = 0        #: track messages acknowledged (QoS 1) / sent (QoS 0)
        self._dropped_full = 0    # queue full (written by the submitting thread only)
        self._dropped_away = 0    # broker away or publish refused (publisher thread)
        self.reconnects = 0
        self.last_error: str | None = None
        self.status_published = 0
        self.sync_published = 0
        self.last_msg_seq = 0     #: newest msg_seq handed to the broker
        self._connects = 0
        self._last_sync_seq = -1
        self._client: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- the caller's side (never blocks) --------------------------------------------------
    def submit(self, items: list[tuple[int, str]]) -> None:
        """Queue numbered ``(msg_seq, json_text)`` messages; a full queue drops (counted)."""
        if not items:
            return
        if len(self._q) >= self.max_queue:
            self._dropped_full += len(items)
        else:
            self._q.append(items)  # atomic; the publisher thread polls

    @property
    def dropped(self) -> int:
        """Track messages dropped: queue full, broker away, publish refused."""
        return self._dropped_full + self._dropped_away

    def stats(self) -> dict[str, Any]:
        """``publish.mqtt`` of ``/api/status``."""
        return {"url": self.url, "connected": self.connected, "published": self.published,
                "dropped": self.dropped, "reconnects": self.reconnects,
                "last_error": self.last_error, "queued": len(self._q),
                "last_msg_seq": self.last_msg_seq, "status_published": self.status_published,
                "sync_published": self.sync_published}

    # -- life cycle --------------------------------------------------------------------------
    def start(self) -> None:
        """Create the client, start paho's network thread (it connects and reconnects)
        and the publisher thread. Never waits for the broker."""
        import paho.mqtt.client as mqtt

        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=self._client_id,
                        clean_session=True)
        if self._username:
            c.username_pw_set(self._username, self._password)
        if self.target.tls:
            try:
                c.tls_set(ca_certs=self._ca_file)
            except (OSError, ValueError) as exc:
                raise ConfigError(f"{self.url}: TLS set-up failed: {exc}") from exc
        c.will_set(self.target.topic("status"), OFFLINE, qos=1, retain=True)
        c.reconnect_delay_set(RECONNECT_MIN_S, RECONNECT_MAX_S)  # type: ignore[arg-type]
        c.max_inflight_messages_set(200)
        c.max_queued_messages_set(1000)  # paho's own queue is bounded too
        c.on_connect = self._on_connect
        c.on_disconnect = self._on_disconnect
        c.on_publish = self._on_publish
        c.on_connect_fail = self._on_connect_fail
        try:
            c.connect_async(self.target.host, self.target.port, keepalive=10)
        except (OSError, ValueError) as exc:
            raise UplinkError(f"{self.url}: {exc}") from exc
        self._client = c
        c.loop_start()
        self._thread = threading.Thread(target=self._run, name="mqtt-publisher", daemon=True)
        self._thread.start()

    def close(self, timeout_s: float = 2.0) -> None:
        """Flush, publish ``{"online": false}`` (retained), disconnect; never raises."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s + 1.0)
        c, self._client = self._client, None
        if c is None:
            return
        try:
            if self.connected:
                info = c.publish(self.target.topic("status"), OFFLINE, qos=1, retain=True)
                info.wait_for_publish(timeout_s)
            c.disconnect()
        except Exception:  # noqa: BLE001 - closing must never raise
            pass
        finally:
            c.loop_stop()
            self.connected = False

    # -- paho's network thread ----------------------------------------------------------------
    def _on_connect(self, client: Any, _u: Any, _f: Any, reason: Any, _p: Any) -> None:
        if getattr(reason, "is_failure", False):
            err = f"broker refused the connection: {reason}"
            if err != self.last_error:  # paho retries every ≤ 2 s: log a change only
                log.warning("%s: %s", self.url, err)
            self.last_error = err
            return
        self._connects += 1
        if self._connects > 1:
            self.reconnects += 1
            log.info("%s: reconnected", self.url)
        self.connected = True

    def _on_disconnect(self, _c: Any, _u: Any, _f: Any, reason: Any, _p: Any) -> None:
        if self.connected and not self._stop.is_set():
            self.last_error = f"broker connection lost: {reason}"
            log.warning("%s: %s", self.url, self.last_error)
        self.connected = False

    def _on_connect_fail(self, _c: Any, _u: Any) -> None:
        self.last_error = "cannot connect to the broker"

    def _on_publish(self, _c: Any, _u: Any, mid: int, _r: Any, _p: Any) -> None:
        with self._lock:
            n = self._pending.pop(mid, None)
            if n is None:
                self._early.add(mid)   # publish() has not returned to our thread yet
            else:
                self.published += n

    # -- the publisher thread ------------------------------------------------------------------
    def _run(self) -> None:
        next_flush = next_status = time.monotonic()
        while True:
            stopping = self._stop.wait(max(min(next_flush, next_status) - time.monotonic(), 0.0))
            now = time.monotonic()
            if stopping or now >= next_flush:
                self._flush()
                if self._sync_fn is not None:
                    self._publish_sync()
                next_flush = now + self.batch_s
            if stopping:
                break
            if now >= next_status:
                self._publish_status()
                next_status = max(next_status + self.status_period_s, now)

    def _flush(self) -> None:
        """Publish what was submitted since the last flush (≤ ``batch_s`` old)."""
        buf: list[tuple[int, str]] = []
        q = self._q
        while q:
            buf.extend(q.popleft())
            if len(buf) >= self.max_batch_messages:
                self._publish_track(buf)
                buf = []
        if buf:
            self._publish_track(buf)

    def _publish(self, topic: str, payload: str, *, messages: int = 0,
                 retain: bool = False) -> Any:
        """paho publish of a payload holding ``messages`` track messages; None (and
        last_error) when not connected or refused."""
        import paho.mqtt.client as mqtt

        c = self._client
        if c is None or not self.connected:
            return None
        try:
            info = c.publish(topic, payload, qos=self.target.qos, retain=retain)
        except (ValueError, RuntimeError, OSError) as exc:
            self.last_error = f"publish to {topic} failed: {exc}"
            return None
        if info.rc != mqtt.MQTT_ERR_SUCCESS:
            self.last_error = f"publish to {topic} failed: {mqtt.error_string(info.rc)}"
            if info.rc == mqtt.MQTT_ERR_NO_CONN and self.target.qos:
                with self._lock:  # paho keeps it and may still send it: not counted twice
                    if info.mid in self._early:
                        self._early.discard(info.mid)
                    elif len(self._pending) < 100_000:
                        self._pending[info.mid] = 0
            return None
        with self._lock:
            if info.mid in self._early:   # acknowledged already
                self._early.discard(info.mid)
                self.published += messages
            else:
                self._pending[info.mid] = messages
        return info

    def _publish_track(self, buf: list[tuple[int, str]]) -> None:
        payload = "[" + ",".join(text for _, text in buf) + "]"
        if self._publish(self.target.topic("track"), payload, messages=len(buf)) is None:
            with self._lock:
                self._dropped_away += len(buf)
            return
        self.last_msg_seq = buf[-1][0]

    def _publish_status(self) -> None:
        try:
            doc = self._status_fn() if self._status_fn is not None else {}
            doc = {"online": True, **doc}
            doc.setdefault("publish", {})
            if isinstance(doc["publish"], dict):
                doc["publish"].setdefault("mqtt", self.stats())
            payload = _json(doc)
        except Exception as exc:  # noqa: BLE001 - a status bug must not stop the track
            self.last_error = f"status: {exc}"
            return
        if self._publish(self.target.topic("status"), payload, retain=True) is not None:
            self.status_published += 1

    def _publish_sync(self) -> None:
        try:
            events = self._sync_fn() if self._sync_fn is not None else []
        except Exception as exc:  # noqa: BLE001
            self.last_error = f"sync events: {exc}"
            return
        for ev in events[-1000:]:
            d = ev.as_dict() if hasattr(ev, "as_dict") else dict(ev)
            key = d.get("msg_seq")
            if key is None or key <= self._last_sync_seq:
                continue
            if self._publish(self.target.topic("sync"), _json(d)) is None:
                return  # retried at the next poll (the broker is away)
            self._last_sync_seq = key
            self.sync_published += 1


class MqttSink(Sink):
    """The sink-registry face of :class:`MqttPublisher`: ``write(batch)`` publishes one
    JSON object per row (non-finite → null) on ``PREFIX/track``, numbered by the batch's
    ``msg_seq`` column when it has one, else by a running count."""

    def __init__(self, target: str, **options: Any) -> None:
        super().__init__(target)
        self.publisher = MqttPublisher(target, **options)
        self.reopen = False  # paho reconnects by itself
        self._count = 0

    def open(self) -> None:
        self.publisher.start()

    def write(self, batch: Batch) -> int:
        names = list(batch.keys())
        cols = [np.asarray(batch[c]) for c in names]
        n = len(cols[0]) if cols else 0
        if n == 0:
            return 0
        rows = [dict(zip(names, vals, strict=True))
                for vals in zip(*(c.tolist() for c in cols), strict=True)]
        items = []
        for r in rows:
            self._count += 1
            seq = int(r["msg_seq"]) if "msg_seq" in r else self._count
            r.setdefault("msg_seq", seq)
            items.append((seq, _json(r)))
        self.publisher.submit(items)
        return n

    def close(self) -> None:
        self.publisher.close()

    def stats(self) -> dict[str, Any]:
        return self.publisher.stats()


def attach_to_service(svc: Any, url: str, **options: Any) -> MqttPublisher:
    """What ``serve --publish URL`` wires: a publisher fed by the service's live pipeline
    (the numbered messages it hands the websocket hub; under ``serve --source replay://``
    they carry ``"replay": true``), its ``status()`` and its recorder's sync events. Call
    before the pipeline starts; ``start()`` / ``close()`` it with the service.
    ``options``: username, password, ca_file, … of :class:`MqttPublisher`."""
    pub = MqttPublisher(url, status=svc.status,
                        sync_events=lambda: svc.recorder.sync_events, **options)
    svc.live.publishers.append(pub.submit)
    return pub
