"""TLM1 uplink over ``socket://``: the service starts while the far end is absent, keeps
trying, and after the far end goes away for 3 s and returns, frames flow again
(reconnects counted on /api/status ``uplink.tlm``)."""

from __future__ import annotations

import socket
import time

from radar_io.benchmarks.service_load import ServeProcess
from radar_io.wirespec.frame import spec_dir

from .test_live_pty import wait_for

SYNC = b"\x1a\xcf"
PATH = str(spec_dir() / "paths" / "demo_track_radar.toml")


def receive(listener: socket.socket, n_bytes: int, timeout_s: float = 15.0) -> tuple[socket.socket, bytes]:
    """Accept one connection and read at least ``n_bytes`` from it."""
    listener.settimeout(timeout_s)
    conn, _ = listener.accept()
    conn.settimeout(timeout_s)
    got = b""
    while len(got) < n_bytes:
        chunk = conn.recv(65536)
        assert chunk, "the uplink closed the connection"
        got += chunk
    return conn, got


def test_tlm1_socket_uplink_absent_at_start_then_gone_for_3_s_reconnects(tmp_path):
    far = socket.socket()
    far.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    far.bind(("127.0.0.1", 0))  # bound, not listening: connections are refused
    port = far.getsockname()[1]
    svc = ServeProcess("sim://?ng_per_min=0", tmp_path / "data",
                       extra=("--path", PATH, "--tlm-out", f"socket://127.0.0.1:{port}",
                              "--auto-record", "manual"))
    conns: list[socket.socket] = []
    try:
        st = svc.wait_ready()
        up = wait_for(lambda: (u := svc.get("/api/status")["uplink"]["tlm"])["last_error"] and u,
                      what="the absent uplink reported")
        assert up["connected"] is False and st["connected"]  # the service runs without it
        far.listen(1)  # the far end appears
        conn, got = receive(far, 2000)
        conns.append(conn)
        up = wait_for(lambda: (u := svc.get("/api/status")["uplink"]["tlm"])["connected"] and u,
                      what="connected")
        assert got.count(SYNC) >= 10  # TLM1 frames (sync word 0x1ACF)
        before = up["reconnects"]
        conn.close()  # the far end goes away for 3 s
        far.close()
        down = wait_for(lambda: not (u := svc.get("/api/status")["uplink"]["tlm"])["connected"]
                        and u, what="the uplink noticed")
        assert down["last_error"]
        time.sleep(3.0)
        far = socket.socket()
        far.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        far.bind(("127.0.0.1", port))
        far.listen(1)
        t0 = time.monotonic()
        conn, got = receive(far, 2000)
        conns.append(conn)
        assert time.monotonic() - t0 < 6.0 + 2.0  # back-off is capped at 5 s
        up = svc.get("/api/status")["uplink"]["tlm"]
        assert up["connected"] and up["reconnects"] > before and got.count(SYNC) >= 10
    finally:
        svc.stop()
        for c in conns:
            c.close()
        far.close()
