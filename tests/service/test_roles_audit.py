"""Roles and the audit trail (issue 22 item 2): tokens with roles from a tokens file, every
control route of the OpenAPI walked with a viewer, an operator and an admin token against a
real uvicorn, and exactly one audit record per control request, refused ones included."""

from __future__ import annotations

import subprocess
import sys
import urllib.request
from collections import Counter
from pathlib import Path
from typing import Any

from radar_io.service.auth import Authenticator, TokensFile
from radar_io.service.config import ServiceConfig

from .liveserver import live_server
from .test_live_never_stops import _arguments, call
from .test_replay_sessions import write_flight

#: the role each control route needs (docs/service.md, "Roles")
NEEDS = {
    ("POST", "/api/recordings/start"): "operator", ("POST", "/api/recordings/stop"): "operator",
    ("POST", "/api/replays"): "operator", ("DELETE", "/api/replays/{sid}"): "operator",
    ("POST", "/api/replays/{sid}/pause"): "operator",
    ("POST", "/api/replays/{sid}/resume"): "operator",
    ("POST", "/api/replays/{sid}/seek"): "operator", ("POST", "/api/replays/{sid}/step"): "operator",
    ("POST", "/api/replays/{sid}/speed"): "operator",
    ("POST", "/api/alarms/{alarm_id}/ack"): "operator", ("POST", "/api/annotations"): "operator",
    ("PUT", "/api/calibration"): "admin", ("POST", "/api/calibration/bias"): "admin",
    ("POST", "/api/runway"): "admin", ("DELETE", "/api/runway/jobs/{job_id}"): "admin",
    ("GET", "/api/audit"): "admin",
}
RANK = {"viewer": 0, "operator": 1, "admin": 2}


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "radar_io.cli", *args], capture_output=True,
                          text=True, timeout=120, check=False)


def test_token_cli_prints_the_token_once_and_stores_only_a_hash(tmp_path):
    f = tmp_path / "tokens.json"
    out = cli("token", "--tokens-file", str(f), "add", "alice", "--role", "operator")
    assert out.returncode == 0, out.stderr
    token = out.stdout.strip()
    assert out.stdout == token + "\n" and token.startswith("rio_")  # alone on stdout
    text = f.read_text()
    assert token not in text and token.split("_", 2)[2] not in text
    assert oct(f.stat().st_mode & 0o777) == "0o600"
    listed = cli("token", "--tokens-file", str(f), "list")
    assert listed.stdout.split("\t")[:2] == ["alice", "operator"] and token not in listed.stdout
    auth = Authenticator(None, str(f))
    assert auth.verify(token).actor == "alice" and auth.cached(token).role == "operator"
    assert auth.verify(token[:-1] + ("A" if token[-1] != "A" else "B")) is None
    assert cli("token", "--tokens-file", str(f), "add", "alice", "--role", "admin"
               ).returncode == 2  # the name is taken
    assert cli("token", "--tokens-file", str(f), "revoke", "alice").returncode == 0
    auth._reload(force=True)
    assert auth.verify(token) is None and TokensFile(f).entries() == []


def _control_ops(api: dict[str, Any]) -> dict[tuple[str, str], dict[str, Any]]:
    """Operations that declare the bearer token (the control routes)."""
    return {(m.upper(), p): op for p, item in api["paths"].items() for m, op in item.items()
            if any("HTTPBearer" in s for s in op.get("security", []))}


def test_every_control_route_by_role_with_one_audit_record_each(tmp_path):
    tf = TokensFile(tmp_path / "tokens.json")
    tokens = {role: tf.add(f"{role}-1", role) for role in RANK}
    rec_dir = tmp_path / "data" / "recordings"
    rec_dir.mkdir(parents=True)
    write_flight(rec_dir / "earlier.rdrlog", 2000, seq0=100, sr=9000)
    cfg = ServiceConfig(source="sim://", data_dir=str(tmp_path / "data"),
                        tokens_file=str(tf.path), auto_record="manual")
    made: list[tuple[str, str, int, str | None]] = []  # method, path, status, actor
    with live_server(cfg) as srv:
        srv.wait_connected()
        api = srv.get("/openapi.json")
        ops = _control_ops(api)
        assert set(ops) == set(NEEDS), sorted(set(ops) ^ set(NEEDS))
        assert srv.get("/api/whoami")["role"] is None
        for role in ("viewer", "operator", "admin"):
            code, who = call(srv.base, "GET", "/api/whoami", token=tokens[role])
            assert code == 200 and who["actor"] == f"{role}-1" and who["role"] == role
        # refused without a token and with a wrong one, too
        for tok in (None, "rio_000000000000_" + "x" * 43):
            code, _ = call(srv.base, "POST", "/api/recordings/start", token=tok)
            assert code == (401 if tok is None else 403)
            made.append(("POST", "/api/recordings/start", code, None))
        ctx = {"live": "earlier", "earlier": "earlier"}
        for role in ("viewer", "operator", "admin"):
            code, doc = call(srv.base, "POST", "/api/replays", {"recording": "earlier"},
                             token=tokens[role])
            made.append(("POST", "/api/replays", code, f"{role}-1"))
            if code == 201:
                ctx["sid"] = doc["id"]
            for (method, path) in sorted(ops, key=lambda mp: (mp[0] == "DELETE", mp)):
                url, body, raw, ctype = _arguments(method, path, ops[(method, path)], ctx)
                code, doc = call(srv.base, method, url, body, raw=raw, content_type=ctype,
                                 token=tokens[role])
                made.append((method, url.split("?")[0], code, f"{role}-1"))
                allowed = RANK[role] >= RANK[NEEDS[(method, path)]]
                if allowed:
                    assert code not in (401, 403) and code < 500, (role, method, url, code, doc)
                else:
                    assert code == 403, (role, method, url, code, doc)
        since = "1970-01-01T00:00:00Z"
        code, doc = call(srv.base, "GET", f"/api/audit?since={since}&limit=100000",
                         token=tokens["admin"])
        assert code == 200
        code_v, _ = call(srv.base, "GET", "/api/audit", token=tokens["operator"])
        assert code_v == 403
    records = doc["records"]
    assert all(set(r) >= {"t_utc", "actor", "role", "action", "method", "path", "params",
                          "remote", "status"} for r in records)
    got = Counter((r["method"], r["path"], r["status"], r["actor"]) for r in records)
    assert got == Counter(made), (got - Counter(made), Counter(made) - got)
    assert all(r["remote"] == "127.0.0.1" and r["t_utc"].endswith("Z") for r in records)
    refused = [r for r in records if r["status"] in (401, 403)]
    assert any(r["role"] == "viewer" for r in refused) and any(r["actor"] is None for r in refused)
    cal = [r for r in records if r["path"] == "/api/calibration" and r["role"] == "admin"]
    assert cal and cal[0]["params"]["id"] == "walk"  # the JSON body, as parameters
    # the file on disk: the same records, one JSON object per line
    lines = (tmp_path / "data" / "audit" / "audit.jsonl").read_text().splitlines()
    assert len(lines) == len(records) + 2  # + the two audit reads themselves
    print(f"\nroles walk: {len(ops)} control operations x 3 roles, {len(made)} requests, "
          f"{len(records)} audit records ({len(refused)} refused)")


def test_require_token_for_read(tmp_path):
    tf = TokensFile(tmp_path / "tokens.json")
    viewer = tf.add("v", "viewer")
    cfg = ServiceConfig(source="sim://", data_dir=str(tmp_path / "data"),
                        tokens_file=str(tf.path), require_token_for_read=True)
    with live_server(cfg) as srv:
        assert call(srv.base, "GET", "/api/status", token=None)[0] == 401
        code, st = call(srv.base, "GET", "/api/status", token=viewer)
        assert code == 200 and st["control_enabled"]
        req = urllib.request.Request(srv.base + "/")  # the dashboard page itself stays open
        with urllib.request.urlopen(req, timeout=10) as r:
            assert r.status == 200


def test_audit_log_rotates_and_reads_in_order(tmp_path):
    from radar_io.service.auth import JsonlLog

    log = JsonlLog(tmp_path / "a.jsonl", max_bytes=2000, keep=3)
    try:
        for k in range(200):
            assert log.append({"k": k, "pad": "x" * 20})
            assert log.flush(10)
        files = log.files()
        assert len(files) == 4 and all(p.stat().st_size <= 2000 for p in files)
        ks = [r["k"] for r in log.read()]
        assert ks == sorted(ks) and ks[-1] == 199 and len(ks) < 200  # oldest rotated away
    finally:
        log.close()
    assert Path(tmp_path / "a.jsonl").exists()
