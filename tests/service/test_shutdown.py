"""Stopping ``serve`` (SIGTERM, as systemd does) while it records and a websocket client
never reads: the process is gone within ``shutdown_timeout_s``, the recording was closed
first and reads back whole (no torn tail), and archiving left undone is finished at the next
start with no ``.part`` file left. The archiver's resume and clean-up on their own too."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

from radar_io.benchmarks.service_load import ServeProcess
from radar_io.recording.rdrlog import RecordingReader, RecordingWriter
from radar_io.service.archiver import RecordingArchiver
from radar_io.simulation.radar import RadarSimulator, SimConfig
from radar_io.wirespec.frame import load_spec

from .liveserver import live_server, service_config

BUDGET_S = 4.0


class StalledClient:
    """A /ws/live client that connects with a small receive window and never reads."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.connected = threading.Event()
        self.done: asyncio.Event | None = None
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(self._run(),),
                                       daemon=True)
        self.thread.start()
        assert self.connected.wait(10), "the websocket did not connect"

    async def _run(self) -> None:
        import websockets

        self.done = asyncio.Event()
        host, port = self.url.split("//", 1)[1].split("/", 1)[0].split(":")
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect((host, int(port)))
        async with websockets.connect(self.url, sock=sock, max_size=None, max_queue=1,
                                      close_timeout=0.1) as ws:
            ws.transport.pause_reading()
            self.connected.set()
            await self.done.wait()
            ws.transport.abort()

    def close(self) -> None:
        if self.done is not None:
            self.loop.call_soon_threadsafe(self.done.set)
        self.thread.join(5)


def _wait(cond, timeout_s: float = 30.0, what: str = "condition"):
    deadline = time.monotonic() + timeout_s
    while True:
        v = cond()
        if v:
            return v
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)


def _parts(archive: Path) -> list[Path]:
    return [p for p in archive.rglob("*") if p.name.endswith(".part")]


def _stalled_download(port: int, rec_id: str) -> socket.socket:
    """A client that asks for a recording and never reads the answer."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    s.sendall(f"GET /api/recordings/{rec_id} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n"
              .encode())
    return s


def test_sigterm_closes_the_recording_first_and_exits_within_the_budget(tmp_path):
    """Two clients that never read: a websocket, and a download of a 16 MiB recording (more
    than the socket buffers hold, so its response can never finish)."""
    root = tmp_path / "svc"
    archive = tmp_path / "archive"
    old = root / "data" / "recordings" / "20260101T000000Z.rdrlog"
    old.parent.mkdir(parents=True)
    with RecordingWriter(old, load_spec(), fsync_interval_s=60) as w:
        block = os.urandom(1 << 20)
        for k in range(16):
            w.write(block, 1_767_225_600 * 10**9 + k * 10**9)
    cfg = tmp_path / "serve.toml"
    cfg.write_text(f'shutdown_timeout_s = {BUDGET_S}\narchive_dir = "{archive}"\n'
                   'auto_record = "always"\n')
    svc = ServeProcess("sim://", root / "data", extra=("--config", str(cfg)))
    client = download = None
    try:
        svc.wait_ready()
        st = _wait(lambda: (s := svc.get("/api/status"))["recording"] and s["frames"] > 500 and s,
                   what="a recording")
        client = StalledClient(svc.base.replace("http", "ws") + "/ws/live")
        download = _stalled_download(svc.port, old.stem)
        time.sleep(1.0)  # their buffers and queues fill up
        t_signal_ns = time.time_ns()
        t0 = time.monotonic()
        svc.proc.send_signal(signal.SIGTERM)
        try:
            svc.proc.wait(BUDGET_S + 10)
        except subprocess.TimeoutExpired:
            raise AssertionError("serve still runs 10 s after its shutdown budget") from None
        took_s = time.monotonic() - t0
    finally:
        err = svc.stop()
        if client is not None:
            client.close()
        if download is not None:
            download.close()
    assert took_s <= BUDGET_S + 1.5, (took_s, err)
    # the reader stopped and the recording closed before anything else was stopped
    stopped = [ln.split("stopped ", 1)[1].split(" in ")[0] for ln in err.splitlines()
               if "radar_io.service INFO stopped " in ln]
    assert stopped[:2] == ["reader", "recorder"], err
    rec = root / "data" / "recordings" / f"{st['recording']}.rdrlog"
    with RecordingReader(rec) as r:
        chunks = list(r)
        report = r.report
    assert report.torn_tail_bytes == 0 and report.corrupt_chunks == 0, report.problems
    assert len(chunks) > 100
    # recorded up to the signal
    assert abs(chunks[-1].t_ns - t_signal_ns) < 2e9, (chunks[-1].t_ns - t_signal_ns) / 1e9

    # the next start archives whatever the stop left undone, and no .part file is left
    cfg2 = service_config(root, auto_record="manual", archive_dir=str(archive))
    with live_server(cfg2) as srv:
        st2 = _wait(lambda: (s := srv.get("/api/status"))["archive"]["pending"] == 0 and s,
                    what="the archive")
    assert st2["archive"]["errors"] == 0
    parts = sorted(p.parent.name for p in archive.rglob("part-0.parquet"))
    assert parts == [f"recording={old.stem}", f"recording={rec.stem}"]
    assert _parts(archive) == []


def _recording(path: Path, seconds: float, t0_ns: int) -> Path:
    sim = RadarSimulator(config=SimConfig(seed=3, rate_hz=1000, go_delay_s=0.0))
    data, _ = sim.generate(int(1000 * seconds))
    with RecordingWriter(path, load_spec(), fsync_interval_s=60) as w:
        for k in range(0, len(data), 2400):
            w.write(data[k:k + 2400], t0_ns + k * 1_000_000 // 24)
    return path


def test_the_archiver_resumes_what_a_stop_left_queued_and_removes_stale_parts(tmp_path):
    recs = tmp_path / "recordings"
    recs.mkdir()
    archive = tmp_path / "archive"
    t0 = 1_780_000_000 * 10**9
    paths = [_recording(recs / f"2026052{k}T100000Z.rdrlog", 4.0, t0 + k * 86_400 * 10**9)
             for k in range(3)]
    # a first run is stopped at once with three recordings queued: at most the one in hand
    # is archived, the others stay queued
    first = RecordingArchiver(archive, dict)
    for p in paths:
        first.submit(p)
    first.close(0.0)
    first._thread.join(60)
    assert first.archived <= 1
    # an archive interrupted mid-write leaves a hidden temporary file beside its partition
    stale = (archive / "site=unknown" / "date=2026-05-23" / "recording=x"
             / ".part-0.parquet.ab12.part")
    stale.parent.mkdir(parents=True, exist_ok=True)
    stale.write_bytes(b"PAR1 half a file")
    done_before = {p: p.stat().st_mtime_ns for p in archive.rglob("part-0.parquet")}
    second = RecordingArchiver(archive, dict, backlog=recs.glob("*.rdrlog"))
    try:
        _wait(lambda: second.stats()["pending"] == 0 and second.resumed + first.archived == 3,
              what="the backlog")
        assert second.errors == 0 and second.stale_parts == 1
        assert not stale.exists() and _parts(archive) == []
        got = sorted(p.parent.name for p in archive.rglob("part-0.parquet"))
        assert got == sorted(f"recording={p.stem}" for p in paths)
        for p, mtime in done_before.items():  # what was archived is not done again
            assert p.stat().st_mtime_ns == mtime
    finally:
        second.close()
    assert all(p.is_file() for p in paths)  # the recordings themselves stay


def test_after_a_crash_the_next_start_archives_the_recording_and_drops_stale_parts(tmp_path):
    """kill -9 while recording (never closed, so never queued) with an archive cut short
    beside it: the next start archives the recording and removes the temporary file."""
    root = tmp_path / "svc"
    archive = tmp_path / "archive"
    cfg = tmp_path / "serve.toml"
    cfg.write_text(f'archive_dir = "{archive}"\nauto_record = "always"\n')
    svc = ServeProcess("sim://", root / "data", extra=("--config", str(cfg)))
    try:
        svc.wait_ready()
        st = _wait(lambda: (s := svc.get("/api/status"))["recording"] and s["frames"] > 500 and s,
                   what="a recording")
        svc.proc.kill()
        svc.proc.wait(10)
    finally:
        svc.stop()
    rec_id = st["recording"]  # e.g. 20261125T223541Z: archived under date=2026-11-25
    partition = archive / "site=demo" / f"date={rec_id[:4]}-{rec_id[4:6]}-{rec_id[6:8]}"
    stale = partition / f"recording={rec_id}" / ".part-0.parquet.k9x2.part"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"PAR1 cut short")
    with live_server(service_config(root, auto_record="manual", archive_dir=str(archive))) as srv:
        arc = _wait(lambda: (a := srv.get("/api/status")["archive"])["pending"] == 0
                    and a["archived"] and a, what="the archive")
    assert arc["resumed"] == 1 and arc["stale_parts_removed"] == 1 and arc["errors"] == 0
    parts = [p.parent.name for p in archive.rglob("part-0.parquet")]
    assert parts == [f"recording={st['recording']}"] and _parts(archive) == []
