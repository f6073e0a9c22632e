"""Hostile pages and hostile requests against a real ``radar-io serve`` on port 0:
DNS rebinding (foreign Host), foreign Origins, oversized headers and bodies (also
chunked), control without the token, too many websocket clients; and the batched
websocket stream."""

from __future__ import annotations

import asyncio
import json
import socket
import urllib.error
import urllib.request

import pytest
import websockets
from websockets.exceptions import ConnectionClosed, InvalidStatus

from radar_io.benchmarks.service_load import ServeProcess

TOKEN = "hostile-test-token"


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    cfg = d / "serve.toml"
    cfg.write_text('ws_max_clients = 3\nallowed_origins = ["https://radar.example.org"]\n'
                   'allowed_hosts = ["radar-gs.local"]\n'
                   'max_body_kb = 64\nmax_header_kb = 8\nauto_record = "manual"\n')
    s = ServeProcess("sim://", d / "data", extra=("--config", str(cfg)),
                     env={"RADAR_IO_TOKEN": TOKEN})
    with s:  # stopped even when it never becomes ready
        yield s


def request(svc, method: str, path: str, body: bytes | None = None,
            headers: dict[str, str] | None = None) -> tuple[int, dict, dict]:
    req = urllib.request.Request(svc.base + path, method=method, data=body, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, dict(r.headers), json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), json.loads(e.read() or b"null")


def reasons(doc: dict) -> str:
    assert isinstance(doc["detail"], list)
    return "; ".join(d["msg"] for d in doc["detail"])


def test_a_foreign_origin_is_refused_on_the_api(svc):
    code, _, doc = request(svc, "GET", "/api/status", headers={"Origin": "https://evil.example"})
    assert code == 403 and "evil.example" in reasons(doc)
    for ok in (f"http://127.0.0.1:{svc.port}", "https://radar.example.org"):
        code, _, doc = request(svc, "GET", "/api/status", headers={"Origin": ok})
        assert code == 200 and doc["connected"], ok
    assert request(svc, "GET", "/api/status")[0] == 200  # no Origin: not a browser


def test_a_foreign_origin_cannot_open_the_live_websocket(svc):
    url = f"ws://127.0.0.1:{svc.port}/ws/live"

    async def main() -> None:
        with pytest.raises(InvalidStatus) as e:
            async with websockets.connect(url, origin="https://evil.example"):
                pass
        assert e.value.response.status_code == 403
        async with websockets.connect(url, origin=f"http://127.0.0.1:{svc.port}") as ws:
            assert "msg_seq" in json.loads(await ws.recv())

    asyncio.run(main())


def test_a_rebinding_host_is_refused_on_http_and_the_websocket(svc):
    """A page at http://rebind.example:PORT whose name now resolves to 127.0.0.1 is
    same-origin with itself (Origin == Host): the Host check refuses it."""
    evil = f"rebind.example:{svc.port}"
    for path in ("/api/status", "/api/track", "/api/recordings", "/api/sync-events"):
        for origin in ({"Origin": f"http://{evil}"}, {}):
            code, _, doc = request(svc, "GET", path, headers={"Host": evil, **origin})
            assert code == 421 and "rebind.example" in reasons(doc), (path, code, doc)
            assert doc["detail"][0]["type"] == "host_not_allowed"
    for host in (f"127.0.0.1:{svc.port}", f"localhost:{svc.port}", f"[::1]:{svc.port}",
                 "LOCALHOST", f"radar-gs.local:{svc.port}"):
        code, _, doc = request(svc, "GET", "/api/status", headers={"Host": host,
                                                                   "Origin": f"http://{host}"})
        assert code == 200 and doc["connected"], host

    async def ws(host: str) -> int:
        sock = socket.create_connection(("127.0.0.1", svc.port))  # the name "resolves" here
        try:
            async with websockets.connect(f"ws://{host}/ws/live", sock=sock,
                                          origin=f"http://{host}") as conn:
                assert "msg_seq" in json.loads(await conn.recv())
                return 101
        except InvalidStatus as exc:
            return exc.response.status_code

    assert asyncio.run(ws(evil)) == 421
    assert asyncio.run(ws(f"radar-gs.local:{svc.port}")) == 101


def test_a_chunked_body_over_the_limit_is_413_on_every_route(svc):
    """No Content-Length: the guard counts the chunks and answers 413 itself, whatever the
    route does with the body it no longer gets (it used to be 400 on JSON routes)."""
    piece = b" " * 8192
    chunk = f"{len(piece):x}\r\n".encode() + piece + b"\r\n"
    for method, path in (("POST", "/api/coordinates/runway-to-radar"),
                         ("PUT", "/api/calibration"), ("POST", "/api/replay"),
                         ("POST", "/api/alarms/x/ack"), ("POST", "/api/runway/manual")):
        s = socket.create_connection(("127.0.0.1", svc.port), timeout=10)
        try:
            s.sendall(f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{svc.port}\r\n"
                      f"Authorization: Bearer {TOKEN}\r\nContent-Type: application/json\r\n"
                      "Transfer-Encoding: chunked\r\n\r\n".encode() + chunk * 9
                      + b"0\r\n\r\n")  # 72 KiB > max_body_kb = 64
            data = b""
            while b"\r\n\r\n" not in data or not data.rstrip().endswith(b"}"):
                more = s.recv(65536)
                if not more:
                    break
                data += more
        finally:
            s.close()
        head, _, body = data.partition(b"\r\n\r\n")
        assert head.split()[1] == b"413", (method, path, data[:300])
        assert "65536" in reasons(json.loads(body)), (method, path)
    assert request(svc, "GET", "/api/status")[0] == 200


def test_oversized_headers_431_and_bodies_413(svc):
    code, _, doc = request(svc, "GET", "/api/status", headers={"X-Padding": "a" * 10_000})
    assert code == 431 and "headers" in reasons(doc)
    big = json.dumps({"id": "x", "biases": {}, "pad": "a" * 70_000}).encode()
    code, _, doc = request(svc, "PUT", "/api/calibration", big,
                           {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"})
    assert code == 413 and "65536" in reasons(doc)


def test_every_control_endpoint_needs_the_token(svc):
    api = request(svc, "GET", "/openapi.json")[2]
    # pure computations change nothing and need no token: coordinates, the manual runway pose;
    # nor do the removed (deprecated) routes, which answer 410 to everyone
    free = ("/api/runway/manual", "/api/coordinates/")
    control = [(m.upper(), p) for p, ops in api["paths"].items() for m in ops
               if m in ("post", "put", "delete", "patch") and not p.startswith(free)
               and not ops[m].get("deprecated")]
    assert len(control) >= 11
    for method, path in control:
        code, hdr, doc = request(svc, method, path, b"{}", {"Content-Type": "application/json"})
        assert code == 401 and hdr.get("www-authenticate", hdr.get("WWW-Authenticate")) == "Bearer", \
            (method, path, doc)
        code, _, doc = request(svc, method, path, b"{}", {"Content-Type": "application/json",
                                                          "Authorization": "Bearer nope"})
        assert code == 403 and reasons(doc) == "wrong token", (method, path)
        assert "401" in api["paths"][path][method.lower()]["responses"], (method, path)


def test_405_names_the_allowed_methods(svc):
    code, hdr, doc = request(svc, "DELETE", "/api/status")
    assert code == 405 and hdr.get("allow", hdr.get("Allow")) == "GET" and reasons(doc)


def test_batch_stream_sends_arrays_and_extra_clients_are_refused(svc):
    url = f"ws://127.0.0.1:{svc.port}/ws/live"

    async def main() -> tuple[list[int], int | None]:
        async with websockets.connect(url + "?batch=1", max_size=None) as ws1, \
                websockets.connect(url) as ws2, websockets.connect(url) as ws3:
            seqs: list[int] = []
            while len(seqs) < 2000:
                arr = json.loads(await ws1.recv())
                assert isinstance(arr, list) and arr
                seqs += [m["msg_seq"] for m in arr]
            # one array per dispatch: on an idle service each read goes out at once (adaptive
            # fan-out), so an array may hold a single message; that arrays grow when the loop
            # is busy is shown by test_fanout_unit
            assert "msg_seq" in json.loads(await ws2.recv()) and await ws3.recv()
            async with websockets.connect(url) as ws4:  # the fourth: refused
                try:
                    await asyncio.wait_for(ws4.recv(), 5)
                except ConnectionClosed as exc:
                    return seqs, exc.rcvd.code if exc.rcvd else None
        return seqs, None

    seqs, code = asyncio.run(main())
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert code == 1013
    st = json.loads(urllib.request.urlopen(svc.base + "/api/status", timeout=5).read())
    assert st["ws_refused"] >= 1


def test_host_policy_and_the_origins_host():
    """Which Host names pass, by bind address and allowed_hosts; an Origin equal to a Host
    that is not allowed does not pass either (the rebinding case at the Origin check)."""
    from radar_io.service.guard import HostPolicy, origin_allowed

    local = HostPolicy([], "127.0.0.1")
    assert all(local.allows(h) for h in ("127.0.0.1:8000", "LOCALHOST:1", "[::1]:8000",
                                         "localhost.", "::1"))
    assert not any(local.allows(h) for h in ("rebind.example:8000", "192.168.1.20:8000",
                                             "127.0.0.2", "[::2]:80", ""))
    lan = HostPolicy(["radar-gs.local"], "0.0.0.0")  # all interfaces: any address, and names listed
    assert lan.allows("192.168.1.20:8000") and lan.allows("[fe80::1]:8000")
    assert lan.allows("Radar-GS.local:8000") and not lan.allows("rebind.example")
    bound = HostPolicy([], "192.168.1.20")
    assert bound.allows("192.168.1.20:8000") and not bound.allows("10.0.0.1:8000")
    assert HostPolicy(["*"]).allows("anything.example")
    evil = "rebind.example:8000"
    assert not origin_allowed(f"http://{evil}", evil, frozenset(), local)
    assert origin_allowed("http://127.0.0.1:8000", "127.0.0.1:8000", frozenset(), local)
    assert origin_allowed("https://radar.example.org/", evil, frozenset({"https://radar.example.org"}),
                          local)
