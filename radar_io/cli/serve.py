"""``radar-io serve``: the live service (REST, websocket, dashboard)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from radar_io.errors import ConfigError


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("serve", help="the live service: REST, websocket and the dashboard",
                       description="Acquire from a source, record, and serve the API and the "
                       "operator dashboard. With no arguments: the built-in simulator on "
                       "http://127.0.0.1:8000/.")
    p.add_argument("--config", metavar="CONFIG.toml", help="service config (see deploy/)")
    p.add_argument("--source", help="sim:// (default), a serial device or pyserial URL, "
                   "replay://PATH.rdrlog?speed=1")
    p.add_argument("--host", help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, help="TCP port (default 8000; 0 = any free port, printed)")
    p.add_argument("--site", help="site TOML (sim:// defaults to the demo site)")
    p.add_argument("--calibration", help="calibration set JSON to apply at start")
    p.add_argument("--data-dir", help="recordings and calibration sets (default ./radar-data)")
    p.add_argument("--auto-record", choices=("go", "manual", "always"),
                   help="record per GO period (default), only on request, or always")
    p.add_argument("--token-file", help="file holding the control token "
                   "(or set RADAR_IO_TOKEN; no token = control disabled)")
    p.add_argument("--tokens-file", metavar="FILE", help="named tokens with roles (viewer, "
                   "operator, admin), hashes only; see radar-io token")
    p.add_argument("--path", help="reference path TOML: deviation needles, DY/DZ in messages")
    p.add_argument("--tlm-out", help="TLM1 uplink: udp://host:port, a serial URL/device or a file")
    p.add_argument("--da-out", help="D/A recorder words: a serial URL/device or a file")
    p.add_argument("--publish", metavar="URL", help="MQTT: mqtt://HOST:PORT/PREFIX[?qos=0|1] or "
                   "mqtts://…; user/password from the config or RADAR_IO_MQTT_USER/PASSWORD")
    p.add_argument("--asterix-out", metavar="URL", help="ASTERIX CAT048 target reports: "
                   "udp://HOST:PORT (one data block per datagram), a serial URL or a file")
    p.add_argument("--can", metavar="INTERFACE:CHANNEL",
                   help="aircraft air data over CAN, e.g. socketcan:can0 or virtual:air")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Validate the config, build the app (refusing what can never work), bind, print the
    real address on stderr (``listening on http://HOST:PORT/``), then serve until stopped."""
    import logging
    import socket

    import uvicorn

    from radar_io.service.app import build_app
    from radar_io.service.config import load_config
    from radar_io.service.shutdown import GracefulServer

    cfg = load_config(args.config, {
        "source": args.source, "host": args.host, "port": args.port, "site": args.site,
        "calibration": args.calibration, "data_dir": args.data_dir,
        "auto_record": args.auto_record, "token_file": args.token_file,
        "tokens_file": args.tokens_file, "path": args.path,
        "tlm_out": args.tlm_out, "da_out": args.da_out, "can": args.can,
        "publish": args.publish, "asterix_out": args.asterix_out})
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    app = build_app(cfg)
    state = app.state.service
    try:
        family = socket.getaddrinfo(cfg.host, cfg.port, type=socket.SOCK_STREAM)[0][0]
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((cfg.host, cfg.port))
    except OSError as exc:  # e.g. address already in use
        raise ConfigError(f"cannot serve on {cfg.host}:{cfg.port}: "
                          f"{exc.strerror or exc}") from exc
    port = sock.getsockname()[1]
    host = f"[{cfg.host}]" if ":" in cfg.host else cfg.host
    print(f"radar-io serve: source {cfg.source}, data in {state.data_dir.resolve()}, control "
          f"{'enabled' if state.auth.enabled else 'disabled (no token configured)'}", file=sys.stderr)
    print(f"listening on http://{host}:{port}/ (dashboard; API docs /docs)", file=sys.stderr,
          flush=True)
    # per-message deflate would compress every measurement once per client: off. Open
    # connections get a fifth of the shutdown budget to close (a client that never reads
    # cannot hold the stop); the recording is closed meanwhile (GracefulServer).
    config = uvicorn.Config(app, log_level="warning", ws_ping_interval=20,
                            ws_per_message_deflate=False,
                            timeout_graceful_shutdown=max(1, int(cfg.shutdown_timeout_s // 5)),
                            h11_max_incomplete_event_size=max(64 << 10, 4 * cfg.max_header_kb << 10))
    try:
        GracefulServer(config, state.begin_shutdown).run(sockets=[sock])
    finally:
        sock.close()
        state.stop()  # no-op after the lifespan's stop; else (a forced exit) the stop now
    return 0
