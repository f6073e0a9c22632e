"""The service in-process on a socket bound to 127.0.0.1 port 0, and headless Chromium, as
context managers and pytest fixtures that stop what they started in ``finally`` — also
when starting fails half-way (a server left running would keep its serial port open)."""

from __future__ import annotations

import json
import socket
import threading
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from radar_io.service.config import ServiceConfig

from .cdp import Chrome, chromium_path

TOKEN = "test-token-dashboard"


class LiveServer:
    """``create_app(cfg)`` served by uvicorn in a thread on a pre-bound listening socket
    (port 0 unless ``port`` is given, e.g. to restart on the same port)."""

    def __init__(self, cfg: ServiceConfig, port: int = 0, routers: tuple[Any, ...] = ()) -> None:
        import uvicorn

        from radar_io.service.app import create_app

        self.app = create_app(cfg)
        for r in routers:  # test peers: matched first, so they win over the app's own routes
            self.app.include_router(r)
            self.app.router.routes.insert(0, self.app.router.routes.pop())
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", port))
        self.port = self.sock.getsockname()[1]
        self.base = f"http://127.0.0.1:{self.port}"
        self.server = uvicorn.Server(uvicorn.Config(self.app, log_level="warning",
                                                    ws_per_message_deflate=False))
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]},
                                       daemon=True, name=f"uvicorn:{self.port}")

    def start(self, timeout_s: float = 30.0) -> None:
        self.thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError(f"the service on port {self.port} did not start")
            time.sleep(0.02)

    def get(self, path: str) -> Any:
        with urllib.request.urlopen(self.base + path, timeout=5) as r:
            return json.loads(r.read())

    def request(self, method: str, path: str, body: Any = None,
                token: str | None = None) -> tuple[int, Any]:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method)
        req.add_header("Content-Type", "application/json")
        if token:
            req.add_header("Authorization", f"Bearer {token}")
        try:
            with urllib.request.urlopen(req, timeout=10) as r:
                return r.status, json.loads(r.read())
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read() or b"null")

    def wait_connected(self, timeout_s: float = 20.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            st = self.get("/api/status")
            if st["connected"]:
                return st
            time.sleep(0.1)
        raise TimeoutError("the service's source did not connect")

    def stop(self) -> None:
        self.server.should_exit = True
        if self.thread.is_alive():
            self.thread.join(15)
        self.sock.close()


def service_config(tmp: Path, source: str = "sim://", **kw: Any) -> ServiceConfig:
    """A config writing into ``tmp``, with a control token from a file."""
    tmp.mkdir(parents=True, exist_ok=True)
    (tmp / "token").write_text(TOKEN)
    return ServiceConfig(source=source, data_dir=str(tmp / "data"),
                         token_file=str(tmp / "token"), **kw)


@contextmanager
def live_server(cfg: ServiceConfig, port: int = 0, routers: tuple[Any, ...] = ()
                ) -> Iterator[LiveServer]:
    srv = LiveServer(cfg, port, routers)
    try:
        srv.start()
        yield srv
    finally:
        srv.stop()


@contextmanager
def chrome_browser(user_data_dir: Path) -> Iterator[Chrome]:
    """Headless Chromium with a fresh profile; skips the test when Chromium is missing."""
    try:
        chromium_path()
    except RuntimeError as exc:
        pytest.skip(str(exc))
    chrome = Chrome(user_data_dir)  # cleans up after itself when it cannot start
    try:
        yield chrome
    finally:
        chrome.close()


@pytest.fixture
def sim_server(tmp_path: Path) -> Iterator[LiveServer]:
    """The service on the built-in simulator (demo site)."""
    with live_server(service_config(tmp_path / "svc")) as srv:
        yield srv


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Chrome]:
    with chrome_browser(tmp_path / "chrome") as chrome:
        yield chrome


def ink_js(canvas_expr: str) -> str:
    """JS: how many pixels of a canvas are drawn (not fully transparent and not background)."""
    return f"""(() => {{ const c = {canvas_expr}; if (!c) return 0;
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4) if (d[i + 3] > 0 && (d[i] + d[i + 1] + d[i + 2]) > 90) n++;
        return n; }})()"""
