"""``serve`` refuses a bad configuration at start: exit code 2 and one line naming the
file and the field; a configuration that can never work (TLM1 without a path) too."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from radar_io.errors import ConfigError
from radar_io.service.config import load_config


def serve(tmp_path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "RADAR_IO_TOKEN"}
    return subprocess.run([sys.executable, "-m", "radar_io.cli", "serve", "--port", "0",
                           "--data-dir", str(tmp_path / "d"), *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("text,field,words", [
    ("prot = 8000\n", "prot", "unknown key"),
    ('port = "8000"\n', "port", "valid integer"),
    ("port = 70000\n", "port", "less than or equal to 65535"),
    ("history_mb = 0\n", "history_mb", "greater than 0"),
    ('auto_record = "sometimes"\n', "auto_record", "'go', 'manual' or 'always'"),
    ('allowed_origins = "https://a.example"\n', "allowed_origins", "valid array"),
    ("ws_max_clients = 2.5\n", "ws_max_clients", "integer"),
    ('can = "can0"\n', "can", "interface:channel"),
])
def test_a_bad_config_file_is_one_line_naming_the_file_and_field(tmp_path, text, field, words):
    cfg = tmp_path / "serve.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(str(cfg), {})
    msg = str(e.value)
    assert str(cfg) in msg and repr(field) in msg and words in msg and "\n" not in msg
    r = serve(tmp_path, "--config", str(cfg))
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(cfg) in lines[0] and field in lines[0], r.stderr


def test_a_good_config_file_and_overrides(tmp_path):
    cfg = tmp_path / "serve.toml"
    cfg.write_text('port = 0\nhistory_mb = 8\nallowed_origins = ["https://a.example"]\n')
    c = load_config(str(cfg), {"port": 1234, "host": None})
    assert (c.port, c.history_mb, c.allowed_origins, c.host) == (1234, 8.0, ["https://a.example"],
                                                                 "127.0.0.1")
    with pytest.raises(ConfigError, match="'port'"):
        load_config(str(cfg), {"port": -1})


@pytest.mark.parametrize("option,field", [("--tlm-out", "tlm_out"), ("--da-out", "da_out")])
def test_uplinks_without_a_path_are_refused_at_start(tmp_path, option, field):
    r = serve(tmp_path, option, "udp://127.0.0.1:9")
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and field in lines[0] and "--path" in lines[0], r.stderr


def test_the_example_config_has_every_key_and_each_is_valid(tmp_path):
    """deploy/config.example.toml with its commented keys switched on loads without error and
    names every key the service accepts (the README points users to it for all keys)."""
    import dataclasses
    import re
    from pathlib import Path

    from radar_io.service.config import ServiceConfig

    text = (Path(__file__).resolve().parents[2] / "deploy" / "config.example.toml").read_text()
    on = re.sub(r"^# ?([a-z0-9_]+ = .*)$", r"\1", text, flags=re.M)   # `# key = value` → on
    on = re.sub(r"^# ?(\[\[alarms\]\])$", r"\1", on, flags=re.M)
    on = re.sub(r"^# ?((column|min|max|for_s|name) = .*)$", r"\1", on, flags=re.M)
    p = tmp_path / "all.toml"
    p.write_text(on)
    cfg = load_config(str(p), {})
    keys = {f.name for f in dataclasses.fields(ServiceConfig)}
    shown = set(re.findall(r"^([a-z0-9_]+) = ", on, flags=re.M)) | {"alarms"}
    assert keys <= shown, sorted(keys - shown)
    assert cfg.publish.startswith("mqtts://") and cfg.alarms[0]["column"] == "dz_m"


SECRET = "s3cr3t-Hunter2-do-not-print"


@pytest.mark.parametrize("text,field", [
    (f'mqtt_password = ["{SECRET}"]\n', "mqtt_password"),
    (f"mqtt_password = {{ value = \"{SECRET}\" }}\n", "mqtt_password"),
    (f'token_file = ["{SECRET}"]\n', "token_file"),
])
def test_a_bad_secret_value_is_named_but_never_echoed(tmp_path, text, field):
    cfg = tmp_path / "serve.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(str(cfg), {})
    assert field in str(e.value) and SECRET not in str(e.value) and e.value.__cause__ is None
    r = serve(tmp_path, "--config", str(cfg))
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert str(cfg) in lines[0] and field in lines[0] and "withheld" in lines[0]
    assert SECRET not in r.stderr + r.stdout


def test_the_token_file_content_is_never_printed(tmp_path):
    bad = tmp_path / "token.bin"
    bad.write_bytes(SECRET.encode() + b"\xff\xfe")  # not UTF-8: refused without its bytes
    r = serve(tmp_path, "--token-file", str(bad), "--source", "nope://x")
    assert r.returncode == 2 and SECRET not in r.stderr + r.stdout
    r = serve(tmp_path, "--token-file", str(bad))
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1 and str(bad) in lines[0] and "UTF-8" in lines[0]
    assert SECRET not in r.stderr + r.stdout and "\\x" not in r.stderr


@pytest.mark.parametrize("source", ["foo://x", "ftp://host/radar", "Sim2://"])
def test_an_unknown_source_scheme_is_refused_at_start(tmp_path, source):
    r = serve(tmp_path, "--source", source)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert "'source'" in lines[0] and "unknown URL scheme" in lines[0]
    assert repr(source.split(":")[0].lower()) in lines[0]


def test_known_schemes_and_device_paths_pass_the_source_check():
    from radar_io.sources import check_source_url

    for url in ("sim://", "replay://x.rdrlog?speed=2", "loop://", "socket://127.0.0.1:7",
                "rfc2217://h:1", "spy://loop://", "hwgrep://ttyUSB", "alt://loop://",
                "/dev/ttyUSB0?baudrate=115200", "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1",
                "COM3"):
        check_source_url(url)
    with pytest.raises(ConfigError, match="unknown URL scheme 'http'"):
        check_source_url("http://127.0.0.1/")
