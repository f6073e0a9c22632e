"""Service configuration: a TOML file, overridden by command-line options.

The control token comes from the environment variable ``RADAR_IO_TOKEN`` or
from the file named by ``token_file``; there is never a default token. With no
token configured the control endpoints are disabled and say so.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from radar_io.errors import ConfigError
from radar_io.wirespec.frame import spec_dir
from radar_io.textfiles import read_toml

TOKEN_ENV = "RADAR_IO_TOKEN"


@dataclass
class ServiceConfig:
    source: str = "sim://"
    host: str = "127.0.0.1"
    port: int = 8000
    site: str | None = None          #: site TOML; sim:// defaults to the demo site
    calibration: str | None = None   #: calibration set JSON applied at start
    data_dir: str = "radar-data"     #: recordings, sync indices, calibration sets
    token_file: str | None = None
    auto_record: str = "go"          #: go | manual | always
    preroll_s: float = 2.0
    retry_s: float = 5.0             #: automatic recording: retry a failed start / write every
    low_space_mb: float = 1024.0     #: status storage.low_space below this much free space
    runway_queue: int = 2            #: runway video jobs waiting behind the running one (429 beyond)
    runway_max_upload_mb: float = 512.0  #: largest runway upload (413 beyond, while reading)
    history_size: int = 120_000      #: messages kept for /api/track and ws resume (2 min at 1 kHz)
    ws_queue_size: int = 5000        #: per websocket client, oldest dropped beyond
    spec: str | None = None
    path: str | None = None          #: reference path TOML: adds dy_m, dz_m, along_m, leg
    tlm_out: str | None = None       #: TLM1 uplink: udp://host:port, a serial URL/device or a file
    tlm_cycle_s: float = 0.02        #: one uplink frame per cycle (the source's 20 ms)
    da_out: str | None = None        #: D/A recorder words: a serial URL/device or a file
    can: str | None = None           #: aircraft air data: python-can "interface:channel"
    can_bitrate: int | None = None
    alarms: list[dict[str, Any]] = field(default_factory=list)  #: [[alarms]] limits (service/alarms.py)
    extra: dict[str, Any] = field(default_factory=dict)

    def resolved_site(self) -> str | None:
        if self.site:
            return self.site
        if self.source.startswith("sim:"):
            return str(spec_dir() / "sites" / "demo.toml")
        return None

    def token(self) -> str | None:
        """The control token, or None (control disabled)."""
        tok = os.environ.get(TOKEN_ENV)
        if tok:
            return tok.strip() or None
        if self.token_file:
            try:
                tok = Path(self.token_file).read_text(encoding="utf-8").strip()
            except OSError as exc:
                raise ConfigError(f"cannot read token file {self.token_file}: {exc.strerror}") from exc
            if not tok:
                raise ConfigError(f"token file {self.token_file} is empty")
            return tok
        return None


def load_config(path: str | None, overrides: dict[str, Any]) -> ServiceConfig:
    """Config from a TOML file (optional) with non-None overrides applied."""
    doc: dict[str, Any] = {}
    if path:
        doc = read_toml(path, "config file")
    known = {f.name for f in fields(ServiceConfig)} - {"extra"}
    unknown = set(doc) - known
    if unknown:
        raise ConfigError(f"config file {path}: unknown key(s) {', '.join(sorted(unknown))}")
    cfg = ServiceConfig(**doc)
    for k, v in overrides.items():
        if v is not None:
            setattr(cfg, k, v)
    if cfg.auto_record not in ("go", "manual", "always"):
        raise ConfigError("auto_record must be go, manual or always")
    if cfg.can is not None and ":" not in cfg.can:
        raise ConfigError(f"can = {cfg.can!r}: expected 'interface:channel', e.g. socketcan:can0")
    if cfg.retry_s <= 0:
        raise ConfigError(f"retry_s = {cfg.retry_s}: must be > 0 seconds")
    if cfg.low_space_mb < 0 or cfg.runway_max_upload_mb <= 0 or cfg.runway_queue < 0:
        raise ConfigError("low_space_mb must be >= 0, runway_max_upload_mb > 0, runway_queue >= 0")
    if not 0 < int(cfg.port) < 65536:
        raise ConfigError(f"port {cfg.port} is out of range")
    return cfg
