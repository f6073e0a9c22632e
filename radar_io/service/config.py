"""Service configuration: a TOML file, overridden by command-line options.

Every field is validated on its own (type, range, choice); an unknown key, a wrong type
or a value out of range is refused in one line naming the file and the field
(:class:`~radar_io.errors.ConfigError`; ``serve`` exits 2); the value is quoted, except
for a key named like a secret (:func:`is_secret_name`). A source URL of an unknown scheme
is refused here too.

The control token comes from the environment variable ``RADAR_IO_TOKEN`` or
from the file named by ``token_file``; there is never a default token. With no
token configured the control endpoints are disabled and say so.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Annotated, Any, Literal

from annotated_types import Ge, Gt, Le

from radar_io.errors import ConfigError
from radar_io.textfiles import read_toml
from radar_io.wirespec.frame import spec_dir

TOKEN_ENV = "RADAR_IO_TOKEN"


@dataclass
class ServiceConfig:
    source: str = "sim://"
    host: str = "127.0.0.1"
    port: Annotated[int, Ge(0), Le(65535)] = 8000  #: 0 = any free port (printed at start)
    site: str | None = None          #: site TOML; sim:// defaults to the demo site
    calibration: str | None = None   #: calibration set JSON applied at start
    data_dir: str = "radar-data"     #: recordings, sync indices, calibration sets
    token_file: str | None = None    #: the admin token (or RADAR_IO_TOKEN)
    tokens_file: str | None = None   #: named tokens with roles, hashes only (radar-io token)
    require_token_for_read: bool = False  #: reads (GET /api/…, /ws/…) need a token too
    auto_record: Literal["go", "manual", "always"] = "go"
    preroll_s: Annotated[float, Ge(0.0), Le(600.0)] = 2.0
    retry_s: Annotated[float, Gt(0.0), Le(3600.0)] = 5.0  #: automatic recording: retry after a disk error
    low_space_mb: Annotated[float, Ge(0.0)] = 1024.0      #: status storage.low_space below this free space
    #: chunks held while the disk fails (MiB)
    recording_buffer_mb: Annotated[float, Gt(0.0), Le(65536.0)] = 64.0
    runway_queue: Annotated[int, Ge(0), Le(100)] = 2      #: runway video jobs waiting (429 beyond)
    runway_job_timeout_s: Annotated[float, Gt(0.0), Le(86400.0)] = 1800.0  #: one video job (s)
    history_mb: Annotated[float, Gt(0.0), Le(4096.0)] = 64.0  #: encoded messages kept (MiB)
    ws_queue_size: Annotated[int, Ge(1), Le(1_000_000)] = 5000  #: per client; oldest skipped beyond
    ws_max_clients: Annotated[int, Ge(1), Le(100_000)] = 500    #: more are refused (close 1013)
    #: 0: adaptive fan-out; > 0: minimum spacing of fan-out dispatches (s)
    ws_batch_interval_s: Annotated[float, Ge(0.0), Le(1.0)] = 0.0
    max_replays: Annotated[int, Ge(0), Le(64)] = 4  #: replay sessions at once (429 beyond)
    replay_idle_s: Annotated[float, Gt(0.0), Le(86400.0)] = 300.0  #: a session nobody watches ends
    allowed_origins: list[str] = field(default_factory=list)  #: besides the same host
    #: Host names served besides loopback and the bound address ("*": no Host check)
    allowed_hosts: list[str] = field(default_factory=list)
    max_reports: Annotated[int, Ge(1), Le(64)] = 2         #: reports built at once (429 beyond)
    max_sync_queries: Annotated[int, Ge(1), Le(64)] = 4    #: a recording's sync events at once
    max_downloads: Annotated[int, Ge(1), Le(256)] = 4      #: recording downloads at once
    max_series_queries: Annotated[int, Ge(1), Le(64)] = 4  #: series queries at once
    max_body_kb: Annotated[int, Ge(1), Le(1 << 20)] = 1024    #: JSON bodies (413 beyond)
    max_upload_mb: Annotated[int, Ge(1), Le(1 << 16)] = 512   #: /api/runway uploads
    max_header_kb: Annotated[int, Ge(1), Le(1024)] = 16       #: all request headers (431 beyond)
    spec: str | None = None
    path: str | None = None          #: reference path TOML: adds dy_m, dz_m, along_m, leg
    #: live tracking filter (docs/tracking.md): white-acceleration spectral density (m²/s³)
    track_q_mps2: Annotated[float, Gt(0.0), Le(1.0e4)] | None = None
    #: measurement σ (default: the site's [radar] sigma_*, else TR-861's 5 m / 0.01125°)
    track_sigma_range_m: Annotated[float, Gt(0.0), Le(1.0e4)] | None = None
    track_sigma_angle_deg: Annotated[float, Gt(0.0), Le(10.0)] | None = None
    tlm_out: str | None = None       #: TLM1 uplink: udp://host:port, a serial URL/device or a file
    tlm_cycle_s: Annotated[float, Ge(0.0), Le(10.0)] = 0.02  #: one uplink frame per cycle
    da_out: str | None = None        #: D/A recorder words: a serial URL/device or a file
    can: str | None = None           #: aircraft air data: python-can "interface:channel"
    can_bitrate: Annotated[int, Gt(0)] | None = None
    publish: str | None = None       #: MQTT: mqtt[s]://HOST:PORT/PREFIX[?qos=0|1] (sinks/mqtt.py)
    mqtt_user: str | None = None     #: or RADAR_IO_MQTT_USER; never printed
    mqtt_password: str | None = None  #: or RADAR_IO_MQTT_PASSWORD; never printed
    mqtt_ca_file: str | None = None  #: mqtts:// CA bundle (default: the system's CAs)
    asterix_out: str | None = None   #: ASTERIX CAT048: udp://host:port, a serial URL/device or a file
    archive_dir: str | None = None   #: archive each closed recording as Parquet (radar-io archive layout)
    shutdown_timeout_s: Annotated[float, Ge(1.0), Le(600.0)] = 10.0  #: SIGTERM → exit budget
    alarms: list[dict[str, Any]] = field(default_factory=list)  #: [[alarms]] (service/alarms.py)

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
            except UnicodeDecodeError:  # not chained: the error holds bytes of the token
                raise ConfigError(f"token file {self.token_file} is not UTF-8 text") from None
            if not tok:
                raise ConfigError(f"token file {self.token_file} is empty")
            return tok
        return None


#: a config key whose name holds one of these words has a secret value: never echoed
SECRET_WORDS = ("password", "token", "secret", "key")


def is_secret_name(name: str) -> bool:
    """Whether a key named ``name`` holds a secret (its value is never put in a message)."""
    low = name.lower()
    return any(w in low for w in SECRET_WORDS)


def _validate(doc: dict[str, Any], where: str) -> ServiceConfig:
    """ServiceConfig from a mapping, field by field; ConfigError names ``where`` and the field."""
    import pydantic

    known = [f.name for f in fields(ServiceConfig)]
    unknown = sorted(set(doc) - set(known))
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(known)})")
    try:
        # JSON mode, strict: a dict for the dataclass, and no "8000" for an int
        cfg = pydantic.TypeAdapter(ServiceConfig).validate_json(json.dumps(doc, default=str),
                                                                strict=True)
    except pydantic.ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        if is_secret_name(loc):  # not chained either: pydantic's own text holds the value
            raise ConfigError(f"{where}: field {loc!r}: {err['msg']} (value withheld)") \
                from None
        raise ConfigError(f"{where}: field {loc!r}: {err['msg']} (got {err.get('input')!r})") \
            from exc
    from radar_io.sources import check_source_url

    try:
        check_source_url(cfg.source)
    except ConfigError as exc:
        raise ConfigError(f"{where}: field 'source': {exc}") from exc
    if cfg.can is not None and ":" not in cfg.can:
        raise ConfigError(f"{where}: field 'can': expected 'interface:channel', e.g. "
                          f"socketcan:can0 (got {cfg.can!r})")
    return cfg


def load_config(path: str | None, overrides: dict[str, Any]) -> ServiceConfig:
    """Config from a TOML file (optional) with non-None overrides applied, validated."""
    doc: dict[str, Any] = {}
    if path:
        doc = read_toml(path, "config file")
    _validate(doc, f"config file {path}" if path else "config")
    merged = {**doc, **{k: v for k, v in overrides.items() if v is not None}}
    return _validate(merged, f"config file {path} + command line" if path else "command line")
