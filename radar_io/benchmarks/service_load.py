"""End-to-end latency and loss over a real pty: write RDR1 frames into one side of a
pseudo-terminal at a fixed rate, serve them with ``radar-io serve``, and receive them
on N websocket clients (one of which never reads). Used by ``radar-io bench`` and the tests.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
import threading
import time
import tty
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from radar_io.simulation.radar import RadarSimulator, SimConfig


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Pty:
    """A pseudo-terminal pair; ``path`` is the device the service opens."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.master, view)
            view = view[n:]

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


def end_process(proc: subprocess.Popen, timeout_s: float = 10.0) -> None:
    """Terminate ``proc`` and wait; kill it if it has not ended after ``timeout_s``."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


class ServeProcess:
    """``radar-io serve`` in a child process on 127.0.0.1, on a port the kernel picks
    (``--port 0``; the real port is read from the ``listening on`` line)."""

    def __init__(self, source: str, data_dir: Path, port: int | None = None,
                 extra: tuple[str, ...] = (), env: dict[str, str] | None = None,
                 start_timeout_s: float = 60.0) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "radar_io.cli", "serve", "--source", source, "--host",
             "127.0.0.1", "--port", str(port or 0), "--data-dir", str(data_dir), *extra],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env={**os.environ, **(env or {})})
        self.stderr_lines: list[str] = []
        found = threading.Event()
        self.port = 0

        def drain() -> None:  # read stderr to the end: a full pipe would block the server
            assert self.proc.stderr is not None
            for raw in self.proc.stderr:
                line = raw.decode(errors="replace")
                self.stderr_lines.append(line)
                if not found.is_set() and "listening on http://" in line:
                    self.port = int(line.split("listening on http://", 1)[1].split("/", 1)[0]
                                    .rsplit(":", 1)[1])
                    found.set()
            found.set()

        self._drain = threading.Thread(target=drain, daemon=True)
        self._drain.start()
        if not found.wait(start_timeout_s) or not self.port:
            err = self.stop()
            raise RuntimeError(f"serve did not start: {err.strip()}")
        self.base = f"http://127.0.0.1:{self.port}"

    def get(self, path: str, timeout_s: float = 5.0) -> Any:
        with urllib.request.urlopen(self.base + path, timeout=timeout_s) as r:
            return json.loads(r.read())

    def wait_ready(self, timeout_s: float = 30.0, connected: bool = True) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                self._drain.join(5)
                raise RuntimeError(f"serve exited: {''.join(self.stderr_lines)}")
            try:
                st = self.get("/api/status")
                if st["connected"] or not connected:
                    return st
            except OSError:
                pass
            time.sleep(0.1)
        raise TimeoutError("service did not become ready")

    def __enter__(self) -> ServeProcess:
        """Wait until it serves (stopping it when it never does)."""
        try:
            self.wait_ready()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> str:
        """Terminate (kill after 10 s); the process's stderr."""
        end_process(self.proc)
        self._drain.join(5)
        return "".join(self.stderr_lines)


@dataclass
class LoadResult:
    frames_written: int
    write_ns: dict[int, int]
    received: list[list[tuple[int, int, dict[str, Any]]]] = field(default_factory=list)
    frames: list[bytes] = field(default_factory=list)

    def latencies_ms(self) -> np.ndarray:
        lat = [(t - self.write_ns[m["msg_seq"]]) / 1e6
               for client in self.received for _, t, m in client if m["msg_seq"] in self.write_ns]
        return np.array(lat)


class _LeanReader(asyncio.Protocol):
    """A websocket reader with little to do per message: the RFC 6455 handshake, the
    server's unmasked frames cut out of each read and stamped with the read's time, pings
    answered. 19 of them at 1 kHz cost the measuring process a few per cent of a core
    (the ``websockets`` client: about half a core), so the figure is the server's latency,
    not the client library's (or the measuring process's queue on a loaded machine)."""

    def __init__(self, path: str, n: int, opened: asyncio.Future[None],
                 finished: asyncio.Future[None]) -> None:
        self.path, self.n = path, n
        self.opened, self.finished = opened, finished
        self.buf = b""
        self.upgraded = False
        self.frames: list[tuple[int, bytes]] = []
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        import base64

        self.transport = transport  # type: ignore[assignment]
        key = base64.b64encode(os.urandom(16)).decode()
        transport.write(f"GET {self.path} HTTP/1.1\r\nHost: 127.0.0.1\r\n"  # type: ignore[attr-defined]
                        "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
                        .encode())

    def data_received(self, data: bytes) -> None:
        t = time.time_ns()
        buf = self.buf + data
        if not self.upgraded:
            end = buf.find(b"\r\n\r\n")
            if end < 0:
                self.buf = buf
                return
            if not buf.startswith(b"HTTP/1.1 101"):
                self._fail(ConnectionError(buf[:end].decode(errors="replace")))
                return
            self.upgraded = True
            buf = buf[end + 4:]
            self.opened.set_result(None)
        i = 0
        while len(buf) - i >= 2:
            op, ln = buf[i] & 0x0F, buf[i + 1] & 0x7F
            h = 2
            if ln == 126:
                if len(buf) - i < 4:
                    break
                ln, h = int.from_bytes(buf[i + 2:i + 4], "big"), 4
            elif ln == 127:
                if len(buf) - i < 10:
                    break
                ln, h = int.from_bytes(buf[i + 2:i + 10], "big"), 10
            if len(buf) - i < h + ln:
                break
            payload = buf[i + h:i + h + ln]
            i += h + ln
            if op == 1 and b'"msg_seq"' in payload:  # a measurement (not an alarm state)
                self.frames.append((t, payload))
            elif op == 9 and self.transport is not None:  # ping → pong (masked, zero mask)
                self.transport.write(bytes((0x8A, 0x80 | ln, 0, 0, 0, 0)) + payload)
            elif op == 8:
                self._fail(ConnectionError("the server closed the websocket"))
                return
        self.buf = buf[i:]
        if len(self.frames) >= self.n and not self.finished.done():
            self.finished.set_result(None)

    def _fail(self, exc: BaseException) -> None:
        for f in (self.opened, self.finished):
            if not f.done():
                f.set_exception(exc)

    def connection_lost(self, exc: Exception | None) -> None:
        self._fail(exc or ConnectionError("connection lost"))


async def _reader(url: str, out: list[tuple[int, int, dict[str, Any]]], n: int,
                  ready: asyncio.Event, counter: list[int]) -> None:
    """Receive ``n`` messages on ``url`` with a :class:`_LeanReader`; ``out`` gets
    ``(index, receive time_ns, message)``."""
    host, rest = url.split("//", 1)[1].split("/", 1)
    addr, port = host.rsplit(":", 1)
    loop = asyncio.get_running_loop()
    opened, finished = loop.create_future(), loop.create_future()
    transport, proto = await loop.create_connection(
        lambda: _LeanReader("/" + rest, n, opened, finished), addr, int(port))
    try:
        await opened
        counter[0] += 1
        if counter[0] >= counter[1]:
            ready.set()
        await finished
    finally:
        transport.abort()
    out.extend((i, t, json.loads(text)) for i, (t, text) in enumerate(proto.frames[:n]))


async def _stalled(url: str, done: asyncio.Event, ready: asyncio.Event, counter: list[int]) -> None:
    import websockets

    host, port = url.split("//", 1)[1].split("/", 1)[0].split(":")
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # before connect: a small window
    sock.connect((host, int(port)))
    async with websockets.connect(url, sock=sock, max_size=None, max_queue=1,
                                  close_timeout=0.1) as ws:
        ws.transport.pause_reading()  # never read: the server's buffers and queue fill up
        counter[0] += 1
        if counter[0] >= counter[1]:
            ready.set()
        await done.wait()
        ws.transport.abort()  # no closing handshake: this client never reads


def run_load(pty: Pty, base_ws: str, rate_hz: float = 1000.0, seconds: float = 5.0,
             clients: int = 20, stalled: int = 1, msg_seq0: int = 0, seed: int = 5,
             frames: list[bytes] | None = None) -> LoadResult:
    """Write ``rate_hz`` frames/s for ``seconds`` into the pty; receive on ``clients`` websockets.

    ``msg_seq0`` is the service's last msg_seq before writing (the k-th frame written
    becomes message ``msg_seq0 + k + 1``). ``frames``: these frames (``seconds`` is then
    their count / ``rate_hz``), else the simulator's.
    """
    if frames is None:
        n = int(rate_hz * seconds)
        sim = RadarSimulator(config=SimConfig(seed=seed, rate_hz=rate_hz, go_delay_s=0.0))
        data, _ = sim.generate(n)
        frames = [data[i * 24:(i + 1) * 24] for i in range(n)]
    n = len(frames)
    seconds = n / rate_hz
    res = LoadResult(n, {}, [[] for _ in range(clients - stalled)], frames)

    def writer(start: threading.Event) -> None:
        start.wait()
        t0 = time.monotonic()
        for k, fr in enumerate(frames):
            d = t0 + k / rate_hz - time.monotonic()
            if d > 0:  # a plain sleep: spinning here would take the readers' CPU and GIL
                time.sleep(d)
            res.write_ns[msg_seq0 + k + 1] = time.time_ns()
            pty.write(fr)

    async def main() -> None:
        url = f"{base_ws}/ws/live"
        ready, done = asyncio.Event(), asyncio.Event()
        counter = [0, clients]
        tasks = [asyncio.create_task(_reader(url, res.received[i], n, ready, counter))
                 for i in range(clients - stalled)]
        stall = [asyncio.create_task(_stalled(url, done, ready, counter)) for _ in range(stalled)]
        await asyncio.wait_for(ready.wait(), 20)
        await asyncio.sleep(0.3)
        start = threading.Event()
        th = threading.Thread(target=writer, args=(start,), daemon=True)
        th.start()
        start.set()
        try:
            await asyncio.wait_for(asyncio.gather(*tasks), seconds + 30)
        finally:
            done.set()
            for t in stall:
                t.cancel()
            await asyncio.gather(*stall, return_exceptions=True)
        th.join()

    with asyncio.Runner(loop_factory=_fast_loop_factory()) as runner:
        runner.run(main())
    return res


def _fast_loop_factory() -> Any:
    """uvloop's event loop when installed (it comes with ``uvicorn[standard]``): the readers'
    events cost less CPU than on the default selector loop."""
    try:
        import uvloop
    except ImportError:
        return None
    return uvloop.new_event_loop


def bench_service(seconds: float = 5.0, clients: int = 20, rate_hz: float = 1000.0
                  ) -> dict[str, Any]:
    """p50/p99/max latency (ms) from pty write to websocket receipt, and the loss."""
    import tempfile

    pty = Pty()
    with tempfile.TemporaryDirectory() as d:
        svc = ServeProcess(pty.path, Path(d), extra=("--auto-record", "manual"))
        try:
            st = svc.wait_ready()
            last = svc.get("/api/track?limit=1")["last_msg_seq"]
            res = run_load(pty, f"ws://127.0.0.1:{svc.port}", rate_hz, seconds, clients,
                           msg_seq0=last)
            status = svc.get("/api/status")
        finally:
            svc.stop()
            pty.close()
    lat = res.latencies_ms()
    got = sum(len(c) for c in res.received)
    return {
        "serve_clients": clients, "serve_rate_hz": rate_hz,
        "serve_latency_p50_ms": float(np.percentile(lat, 50)),
        "serve_latency_p99_ms": float(np.percentile(lat, 99)),
        "serve_latency_max_ms": float(lat.max()),
        "serve_messages_expected": res.frames_written * (clients - 1),
        "serve_messages_received": got,
        "serve_ws_dropped_for_stalled_client": status["ws_dropped"],
        "serve_frames": status["frames"] - st["frames"],
    }


def rss_mb(pid: int) -> float:
    """Resident set size of a process (MiB), from /proc."""
    with open(f"/proc/{pid}/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _fanout_worker(url: str, n: int, batch: bool, connected: Any, stop: Any) -> list[bytes]:
    """One client process: ``n`` websocket clients until ``stop`` is set; per client the
    ``(first, last)`` msg_seq of every frame received (an ``array('q')`` in bytes). Nothing
    is JSON-parsed: a frame's messages are consecutive, so only its first and last
    msg_seq are read out of the text (and their count checked)."""
    import re
    from array import array

    import websockets

    key = b'"msg_seq":'
    num = re.compile(rb"\d+")
    done = asyncio.Event()

    async def watch() -> None:
        while not await asyncio.to_thread(stop.wait, 0.5):
            pass
        done.set()

    def seq_at(msg: bytes, i: int) -> int:
        m = num.match(msg, i + len(key))
        return int(m.group()) if m else -1

    async def client(spans: array[int]) -> None:
        async with websockets.connect(url, max_size=None, open_timeout=120) as ws:
            connected.put(1)
            while not done.is_set():
                try:
                    msg = await asyncio.wait_for(ws.recv(decode=False), 0.5)
                except TimeoutError:
                    continue
                first, last = seq_at(msg, msg.find(key)), seq_at(msg, msg.rfind(key))
                if batch and msg.count(key) != last - first + 1:
                    first = last = -1  # not consecutive: counted as lost
                spans.extend((first, last))

    async def main() -> list[bytes]:
        out = [array("q") for _ in range(n)]
        w = asyncio.create_task(watch())
        await asyncio.gather(*(client(a) for a in out), return_exceptions=True)
        await w
        return [a.tobytes() for a in out]

    return asyncio.run(main())


_POLL = """
import json, sys, time, urllib.request
url, until, every = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
lat = []
while time.time() < until:
    t0 = time.perf_counter()
    try:
        urllib.request.urlopen(url, timeout=30).read()
        lat.append((time.perf_counter() - t0) * 1e3)
    except OSError:
        lat.append(float("inf"))
    time.sleep(every)
print(json.dumps(lat))
"""


def bench_fanout(clients: int = 200, rate_hz: float = 1000.0, seconds: float = 10.0,
                 batch: bool = True, status_every_s: float = 0.05, settle_s: float = 5.0,
                 processes: int = 2, interval_s: float | None = None) -> dict[str, Any]:
    """``clients`` websocket clients on one ``serve`` (simulator at ``rate_hz``) for
    ``seconds``: /api/status latency (p50/p99/max, ms) polled by a separate process
    meanwhile, messages per client among those published in the window, messages lost,
    the server's ``ws_dropped``, and the server's RSS (MiB): idle with data flowing
    before, peak during, and ``settle_s`` after the clients left. The clients run in
    ``processes`` child processes, so the poller and the clients do not share a GIL."""
    import multiprocessing as mp
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        cfg = Path(d) / "serve.toml"
        cfg.write_text(f'auto_record = "manual"\nws_max_clients = {clients + 10}\n' +
                       (f"ws_batch_interval_s = {interval_s}\n" if interval_s is not None else ""))
        svc = ServeProcess(f"sim://?rate_hz={rate_hz:g}&ng_per_min=0", Path(d) / "data",
                           extra=("--config", str(cfg)))
        pid = svc.proc.pid
        ctx = mp.get_context("spawn")
        try:
            svc.wait_ready()
            time.sleep(2.0)
            rss_before = rss_mb(pid)
            url = f"ws://127.0.0.1:{svc.port}/ws/live" + ("?batch=1" if batch else "")
            manager = ctx.Manager()
            connected, stop = manager.Queue(), manager.Event()
            share = [clients // processes + (k < clients % processes) for k in range(processes)]
            t_connect = time.time()
            with ctx.Pool(processes) as pool:
                jobs = [pool.apply_async(_fanout_worker, (url, n, batch, connected, stop))
                        for n in share if n]
                for _ in range(clients):
                    connected.get(timeout=60)
                t_ready = time.time()
                seq0 = svc.get("/api/track?limit=1", 60)["last_msg_seq"]
                poll = subprocess.Popen([sys.executable, "-c", _POLL, svc.base + "/api/status",
                                         str(t_ready + seconds), str(status_every_s)],
                                        stdout=subprocess.PIPE, text=True)
                rss_during = []
                while time.time() < t_ready + seconds:
                    rss_during.append(rss_mb(pid))
                    time.sleep(0.2)
                seq1 = svc.get("/api/track?limit=1", 60)["last_msg_seq"]
                lat = np.array(json.loads(poll.communicate(timeout=120)[0]))
                time.sleep(2.0)  # the window's last messages are still on their way
                stop.set()
                results = [j.get(timeout=60.0 + seconds + 60.0) for j in jobs]
            st = svc.get("/api/status", 60)
            time.sleep(settle_s)
            rss_after = rss_mb(pid)
        finally:
            svc.stop()
            if "manager" in locals():
                manager.shutdown()
    got = []
    for per_process in results:
        for raw in per_process:
            span = np.frombuffer(raw, dtype=np.int64).reshape(-1, 2)
            lo = np.maximum(span[:, 0], seq0 + 1)
            hi = np.minimum(span[:, 1], seq1)
            got.append(int(np.clip(hi - lo + 1, 0, None)[span[:, 0] >= 0].sum()))
    per_client = np.array(got)
    published = seq1 - seq0
    return {
        "fanout_clients": clients, "fanout_rate_hz": rate_hz, "fanout_seconds": seconds,
        "fanout_batch": batch, "ws_batch_interval_s": interval_s, "connect_s": round(t_ready - t_connect, 1),
        "status_requests": int(lat.size),
        "status_p50_ms": float(np.percentile(lat, 50)),
        "status_p99_ms": float(np.percentile(lat, 99)),
        "status_max_ms": float(lat.max()),
        "messages_published": int(published),
        "messages_per_client_median": float(np.median(per_client)),
        "messages_per_client_min": int(per_client.min()),
        "messages_per_client_max": int(per_client.max()),
        "messages_per_client_min_share": float(per_client.min() / max(published, 1)),
        "lost_per_client_median": float(published - np.median(per_client)),
        "lost_total": int(published * len(per_client) - per_client.sum()),
        "server_ws_dropped": int(st["ws_dropped"]),
        "history_bytes": int(st.get("history_bytes", 0)),
        "history_messages": int(st.get("history_messages", 0)),
        "rss_before_mb": round(rss_before, 1), "rss_during_max_mb": round(max(rss_during), 1),
        "rss_after_mb": round(rss_after, 1),
    }


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description="websocket fan-out load on radar-io serve")
    ap.add_argument("--clients", type=int, default=200)
    ap.add_argument("--rate-hz", type=float, default=1000.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--no-batch", action="store_true", help="one message per websocket frame")
    ap.add_argument("--processes", type=int, default=2, help="client processes")
    ap.add_argument("--interval-s", type=float, help="the server's ws_batch_interval_s")
    a = ap.parse_args()
    print(json.dumps(bench_fanout(a.clients, a.rate_hz, a.seconds, not a.no_batch,
                                  processes=a.processes, interval_s=a.interval_s), indent=2))
