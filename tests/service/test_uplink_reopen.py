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
        back_s = time.monotonic() - t0
        print(f"\nTLM1 socket:// uplink: far end back after 3 s away, frames again in {back_s:.2f} s")
        assert back_s < 6.0 + 2.0  # back-off is capped at 5 s
        up = svc.get("/api/status")["uplink"]["tlm"]
        assert up["connected"] and up["reconnects"] > before and got.count(SYNC) >= 10
    finally:
        svc.stop()
        for c in conns:
            c.close()
        far.close()


def read_pty(pty, n_bytes: int, timeout_s: float = 15.0) -> bytes:
    """At least ``n_bytes`` from the master side of a pty."""
    import os
    import select

    got = b""
    deadline = time.monotonic() + timeout_s
    while len(got) < n_bytes:
        left = deadline - time.monotonic()
        assert left > 0, f"only {len(got)} bytes from the uplink"
        r, _, _ = select.select([pty.master], [], [], left)
        if r:
            got += os.read(pty.master, 65536)
    return got


def test_da_uplink_on_a_pty_closed_and_recreated_reconnects(tmp_path):
    """D/A words to a serial device (the udev link of a USB adapter): the adapter is pulled
    (pty closed) and plugged back (a new pty behind the same link): words flow again."""
    import os

    from radar_io.benchmarks.service_load import Pty

    link = tmp_path / "da"
    pty1 = Pty()
    os.symlink(pty1.path, link)
    svc = ServeProcess("sim://?ng_per_min=0", tmp_path / "data",
                       extra=("--path", PATH, "--da-out", str(link), "--auto-record", "manual"))
    pty2 = None
    try:
        svc.wait_ready()
        assert len(read_pty(pty1, 4000)) >= 4000
        up = wait_for(lambda: (u := svc.get("/api/status")["uplink"]["da"])["connected"] and u,
                      what="connected")
        before = up["reconnects"]
        pty1.close()  # pulled
        wait_for(lambda: not svc.get("/api/status")["uplink"]["da"]["connected"],
                 what="the uplink noticed")
        pty2 = Pty()  # plugged back: a new device behind the same link
        os.unlink(link)
        os.symlink(pty2.path, link)
        assert len(read_pty(pty2, 4000)) >= 4000
        up = svc.get("/api/status")["uplink"]["da"]
        assert up["connected"] and up["reconnects"] > before and up["last_error"]
    finally:
        svc.stop()
        pty1.close()
        if pty2 is not None:
            pty2.close()
