"""The ``radar-io`` command line: simulate, decode, monitor, bench (and the plug-in commands)."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import os
import sys
import time
from typing import Any, NoReturn

from radar_io.errors import ConfigError, RadarIOError

#: modules that contribute sub-commands through ``add_subparser(subparsers)``
PLUGIN_MODULES = ("radar_io.cli.calibrate", "radar_io.cli.runway", "radar_io.cli.airborne")


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump) and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _load_common(args: argparse.Namespace) -> dict[str, Any]:
    from radar_io.decoding.biases import load_calibration
    from radar_io.coordinates.transforms import load_site
    from radar_io.wirespec.frame import load_spec

    return {
        "spec": load_spec(args.spec) if getattr(args, "spec", None) else load_spec(),
        "site": load_site(args.site) if getattr(args, "site", None) else None,
        "calibration": load_calibration(args.calibration) if getattr(args, "calibration", None)
        else None,
    }


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--site", metavar="SITE", help="site TOML (adds runway and geodetic columns)")
    p.add_argument("--calibration", metavar="CAL", help="calibration set JSON (radar biases)")
    p.add_argument("--spec", metavar="SPEC", help="frame spec TOML (default firmware_specs/rdr1.toml)")


# ---------------------------------------------------------------- decode
def cmd_decode(args: argparse.Namespace) -> int:
    from radar_io.decoding.decoders import iter_decode
    from radar_io.coordinates.reference_path import add_deviation
    from radar_io.sinks.table import MeasurementWriter, Progress
    from radar_io.recording.rdrlog import ReadReport, iter_payloads

    common = _load_common(args)
    path, tlm, da = _guidance_outputs(args)  # bad options fail before any output is created
    fmt = args.format or ("jsonl" if args.output and args.output.endswith((".jsonl", ".json"))
                          else "csv")
    if args.input != "-" and not os.path.exists(args.input):
        raise ConfigError(f"input not found: {args.input}")
    progress = Progress("decode", enabled=not args.quiet)
    report = ReadReport()
    if args.input == "-":
        stdin = sys.stdin.buffer
        chunks = iter(lambda: stdin.read1(1 << 20), b"")
    else:
        chunks = iter_payloads(args.input, progress=lambda d, t: _progress(progress, d, t, state),
                               report=report)
    state: dict[str, Any] = {"frames": 0}
    try:
        out = (open(args.output, "w", encoding="utf-8", newline="") if args.output
               else sys.stdout)
    except OSError as exc:
        raise ConfigError(f"cannot write {args.output}: {exc.strerror}") from None
    stats: dict[str, int] = {}
    try:
        writer = None
        for batch in iter_decode(chunks, **common):
            if path is not None:
                batch = add_deviation(batch, path)
            if writer is None:
                writer = MeasurementWriter(out, batch.columns, fmt)
            writer.write(batch)
            if tlm is not None:
                tlm.send(batch)
            if da is not None:
                da.send(batch)
            state["frames"] = batch.stats["frames"]
            stats = batch.stats
        out.flush()
    except BrokenPipeError:
        sys.stderr.close()  # downstream closed (e.g. `| head`): stop quietly
        return 0
    finally:
        if out is not sys.stdout:
            out.close()
        for sink in (tlm, da):
            if sink is not None:
                sink.close()
    for name, sink in (("tlm-out", tlm), ("da-out", da)):
        if sink is not None and not args.quiet:
            enc = sink.encoder
            sat = {k: v for k, v in enc.saturation.items() if v}
            print(f"radar-io decode: {name}: {enc.frames if name == 'tlm-out' else enc.samples} "
                  f"records, saturated {sat or 'none'}", file=sys.stderr)
    for problem in report.problems:
        print(f"radar-io decode: warning: {args.input}: {problem}", file=sys.stderr)
    progress.close(", ".join(f"{k} {v}" for k, v in stats.items()))
    if args.stats:
        doc = {**stats, "recording": {
            "corrupt_chunks": report.corrupt_chunks, "skipped_bytes": report.skipped_bytes,
            "torn_tail_bytes": report.torn_tail_bytes}} if report.chunks else stats
        try:
            with open(args.stats, "w", encoding="utf-8") as f:
                json.dump(doc, f, indent=2)
                f.write("\n")
        except OSError as exc:
            raise ConfigError(f"cannot write {args.stats}: {exc.strerror}") from None
    return 0


def _guidance_outputs(args: argparse.Namespace) -> tuple[Any, Any, Any]:
    """The reference path and the TLM1 / D/A file sinks asked for on the command line."""
    path = tlm = da = None
    if args.path:
        from radar_io.coordinates.reference_path import load_path

        path = load_path(args.path)
    if args.tlm_out or args.da_out:
        from radar_io.sinks import open_sink

        tlm = open_sink("tlm1", args.tlm_out) if args.tlm_out else None
        da = open_sink("da", args.da_out) if args.da_out else None
    return path, tlm, da


def _progress(progress: Any, done: int, total: int, state: dict[str, Any]) -> None:
    progress.total = total
    progress.update(done, f"{state['frames']} frames")


# ---------------------------------------------------------------- simulate
def cmd_simulate(args: argparse.Namespace) -> int:
    from radar_io.recording.rdrlog import RecordingWriter
    from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig
    from radar_io.sources.serialport import is_serial_target, open_port

    script = FlightScript(**{k: getattr(args, k) for k in FlightScript.__dataclass_fields__
                             if getattr(args, k) is not None})
    cfg = SimConfig(rate_hz=args.rate_hz, seed=args.seed, ng_per_min=args.ng_per_min,
                    sync_every_s=args.sync_every_s, go_delay_s=args.go_delay_s,
                    flip_rate=args.flip_rate, drop_rate=args.drop_rate,
                    insert_rate=args.insert_rate, loop=args.duration_s is not None)
    for name in ("rate_hz", "speed_mps", "length_m"):
        if getattr(args, name) is not None and getattr(args, name) <= 0:
            raise ConfigError(f"--{name.replace('_', '-')} must be positive")
    sim = RadarSimulator(script, cfg, _load_common(args)["spec"])
    target = args.output
    is_port = is_serial_target(target)
    realtime = args.realtime if args.realtime is not None else is_port
    write: Any
    if target == "-":
        write, close = sys.stdout.buffer.write, sys.stdout.buffer.flush
    elif is_port:
        port = open_port(target)
        write, close = port.write, port.close
    elif target.endswith(".rdrlog"):
        rec = RecordingWriter(target, sim.spec, source="simulate")
        t_start = time.time_ns()

        def write(data: bytes) -> None:  # receive time = simulated time of the block's end
            rec.write(data, t_start + int(sim.state.frame_index / args.rate_hz * 1e9))

        close = rec.close
    else:
        try:
            f = open(target, "wb")
        except OSError as exc:
            raise ConfigError(f"cannot write {target}: {exc.strerror}") from None
        write, close = f.write, f.close
    total = args.duration_s if args.duration_s is not None else script.duration_s
    sent = 0
    t0 = time.monotonic()
    try:
        for data in sim.stream(block_s=0.02, duration_s=args.duration_s, realtime=realtime):
            write(data)
            sent += 1
            if not args.quiet and target != "-" and sent % 50 == 0:
                done = sim.state.frame_index / args.rate_hz
                print(f"\rsimulate: {done:7.1f} / {total:.1f} s  {sim.state.frame_index} frames",
                      end="", file=sys.stderr, flush=True)
    except BrokenPipeError:
        return 0
    finally:
        close()
    if not args.quiet and target != "-":
        print(f"\rsimulate: {sim.state.frame_index} frames in {time.monotonic() - t0:.1f} s"
              f" to {target}; corruption {sim.state.counts}", file=sys.stderr)
    return 0


# ---------------------------------------------------------------- monitor
def cmd_monitor(args: argparse.Namespace) -> int:
    from radar_io.decoding.decoders import FrameDecoder
    from radar_io.errors import SourceError
    from radar_io.framing.framers import Framer
    from radar_io.sources import open_source

    common = _load_common(args)
    src = open_source(args.source)
    framer = Framer(common["spec"])
    dec = FrameDecoder(common["spec"], common["calibration"], common["site"])
    src.open()
    t_end = time.monotonic() + args.duration_s if args.duration_s else None
    last: dict[str, Any] | None = None
    t_print = 0.0
    n_rate, t_rate, rate = 0, time.monotonic(), 0.0
    tty = sys.stdout.isatty()
    try:
        while t_end is None or time.monotonic() < t_end:
            try:
                data = src.read(0.1)
            except SourceError as exc:
                print(f"\nradar-io monitor: {exc}; reconnecting", file=sys.stderr)
                src.close()
                time.sleep(1.0)
                src.open()
                continue
            for frame in framer.feed(data):
                last = dec.decode(frame)
                n_rate += 1
            now = time.monotonic()
            if now - t_rate >= 1.0:
                rate, n_rate, t_rate = n_rate / (now - t_rate), 0, now
            if last is not None and now - t_print >= (0.2 if tty else 2.0):
                t_print = now
                line = _monitor_line(last, framer.stats.as_dict(), rate)
                print(("\r" + line) if tty else line, end="" if tty else "\n", flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        src.close()
        if tty:
            print()
    return 0


def _monitor_line(m: dict[str, Any], st: dict[str, int], rate: float) -> str:
    def f(v: Any, fmt: str) -> str:
        return "   ----" if v is None else format(v, fmt)

    lamps = " ".join(n.upper() if m.get(n) else "." * len(n)
                     for n in ("go", "rx_good", "sync", "auto"))
    return (f"SEQ {m['seq']:5d}  SR {f(m['sr_c_m'], '8.1f')} m  EL {f(m['el_c_deg'], '7.3f')}°"
            f"  AZ {f(m['az_c_deg'], '7.3f')}°  X {f(m['x_m'], '8.0f')} Y {f(m['y_m'], '8.0f')}"
            f" H {f(m['h_m'], '6.0f')} m  [{lamps}]  {rate:6.0f} fr/s"
            f"  crc {st['crc_errors']} gaps {st['seq_gaps']} junk {st['bytes_discarded']} B")


# ---------------------------------------------------------------- serve
def cmd_serve(args: argparse.Namespace) -> int:
    import logging

    import uvicorn

    from radar_io.service.app import create_app
    from radar_io.service.config import load_config

    cfg = load_config(args.config, {
        "source": args.source, "host": args.host, "port": args.port, "site": args.site,
        "calibration": args.calibration, "data_dir": args.data_dir,
        "auto_record": args.auto_record, "token_file": args.token_file, "path": args.path,
        "tlm_out": args.tlm_out, "da_out": args.da_out, "can": args.can})
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    app = create_app(cfg)
    svc = app.state.service
    print(f"radar-io serve: source {cfg.source}, dashboard http://{cfg.host}:{cfg.port}/ "
          f"(API docs /docs), data in {svc.data_dir.resolve()}, control "
          f"{'enabled' if svc.token else 'disabled (no token configured)'}", file=sys.stderr)
    try:
        # per-message deflate would compress every measurement once per client: off
        uvicorn.run(app, host=cfg.host, port=int(cfg.port), log_level="warning",
                    ws_ping_interval=20, ws_per_message_deflate=False)
    except OSError as exc:  # e.g. address already in use
        raise ConfigError(f"cannot serve on {cfg.host}:{cfg.port}: {exc.strerror}") from None
    return 0


# ---------------------------------------------------------------- bench
def cmd_bench(args: argparse.Namespace) -> int:
    from radar_io.benchmarks.core import run_bench

    result = run_bench(frames=args.frames, repeat=args.repeat, include_plugins=not args.core_only,
                       serve_seconds=0.0 if args.core_only else args.serve_seconds)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k:45s} {v:,.1f}" if isinstance(v, float) else f"{k:45s} {v}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="radar-io", description="Ground tracking radar interface for flight "
                    "test: decode, record, simulate, serve and calibrate.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("decode", help="decode a raw capture or .rdrlog to CSV / JSON lines",
                       description="Decode RDR1 frames from a raw capture (any bytes) or a "
                       ".rdrlog recording; one row per accepted frame.")
    p.add_argument("input", metavar="INPUT", help="raw capture or .rdrlog ('-' for stdin)")
    p.add_argument("-o", "--output", metavar="OUT", help="output file (default stdout)")
    p.add_argument("--format", choices=("csv", "jsonl"), help="default from OUT's extension, else csv")
    p.add_argument("--stats", metavar="STATS.json", help="write the framer counters here")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--path", metavar="PATH", help="reference path TOML: adds dy_m,dz_m,along_m,leg")
    p.add_argument("--tlm-out", metavar="FILE", help="one TLM1 uplink frame per valid sample "
                   "(needs --path and --site for the default channels)")
    p.add_argument("--da-out", metavar="FILE", help="the 8 D/A recorder words per sample "
                   "(big-endian u16; needs --path)")
    _add_common(p)
    p.set_defaults(func=cmd_decode)

    p = sub.add_parser("simulate", help="synthesise RDR1 frames for a scripted flight",
                       description="Synthesise RDR1 frames for a straight flight at constant "
                       "height, to a file (.rdrlog: a recording), stdout or a serial URL.")
    p.add_argument("-o", "--output", default="-", metavar="OUT",
                   help="'-' (stdout, default), a file, a .rdrlog or a serial URL/device")
    p.add_argument("--duration-s", type=float, help="seconds to simulate (default: one approach)")
    p.add_argument("--rate-hz", type=float, default=1000.0)
    p.add_argument("--start-x-m", type=float, help="start, metres north of the radar")
    p.add_argument("--start-y-m", type=float, help="start, metres east of the radar")
    p.add_argument("--height-m", type=float, help="height above the antenna (default 600)")
    p.add_argument("--course-deg", type=float, help="true course (default 340)")
    p.add_argument("--speed-mps", type=float, help="ground speed (default 70)")
    p.add_argument("--length-m", type=float, help="flight length (default 15000)")
    p.add_argument("--sync-every-s", type=float, default=5.0, help="camera shutter period")
    p.add_argument("--ng-per-min", type=float, default=2.0, help="NG dropouts per minute")
    p.add_argument("--go-delay-s", type=float, default=1.0)
    p.add_argument("--flip-rate", type=float, default=0.0, help="bit flips per byte")
    p.add_argument("--drop-rate", type=float, default=0.0, help="dropped bytes per byte")
    p.add_argument("--insert-rate", type=float, default=0.0, help="inserted bytes per byte")
    p.add_argument("--seed", type=int, default=1)
    rt = p.add_mutually_exclusive_group()
    rt.add_argument("--realtime", dest="realtime", action="store_true", default=None,
                    help="pace output in real time (default for serial outputs)")
    rt.add_argument("--no-realtime", dest="realtime", action="store_false")
    p.add_argument("-q", "--quiet", action="store_true")
    p.add_argument("--spec", metavar="SPEC", help="frame spec TOML")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("monitor", help="live table of a source in the terminal",
                       description="Read a source, decode frame by frame and show a live line.")
    p.add_argument("--source", default="sim://", help="sim:// (default), serial URL or replay://")
    p.add_argument("--duration-s", type=float, help="stop after this many seconds")
    _add_common(p)
    p.set_defaults(func=cmd_monitor)

    p = sub.add_parser("serve", help="the live service: REST, websocket and the dashboard",
                       description="Acquire from a source, record, and serve the API and the "
                       "operator dashboard. With no arguments: the built-in simulator on "
                       "http://127.0.0.1:8000/.")
    p.add_argument("--config", metavar="CONFIG.toml", help="service config (see deploy/)")
    p.add_argument("--source", help="sim:// (default), a serial device or pyserial URL, "
                   "replay://PATH.rdrlog?speed=1")
    p.add_argument("--host", help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, help="TCP port (default 8000)")
    p.add_argument("--site", help="site TOML (sim:// defaults to the demo site)")
    p.add_argument("--calibration", help="calibration set JSON to apply at start")
    p.add_argument("--data-dir", help="recordings and calibration sets (default ./radar-data)")
    p.add_argument("--auto-record", choices=("go", "manual", "always"),
                   help="record per GO period (default), only on request, or always")
    p.add_argument("--token-file", help="file holding the control token "
                   "(or set RADAR_IO_TOKEN; no token = control disabled)")
    p.add_argument("--path", help="reference path TOML: deviation needles, DY/DZ in messages")
    p.add_argument("--tlm-out", help="TLM1 uplink: udp://host:port, a serial URL/device or a file")
    p.add_argument("--da-out", help="D/A recorder words: a serial URL/device or a file")
    p.add_argument("--can", metavar="INTERFACE:CHANNEL",
                   help="aircraft air data over CAN, e.g. socketcan:can0 or virtual:air")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("bench", help="throughput benchmarks",
                       description="Frames/s of the per-frame and batch paths and a memcpy "
                       "reference, measured in the same run.")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--frames", type=int, default=2_000_000, help="frames in the batch test stream")
    p.add_argument("--repeat", type=int, default=5, help="best of N runs")
    p.add_argument("--serve-seconds", type=float, default=5.0,
                   help="length of the live-service latency run: 1 kHz frames written into a "
                   "pty, 20 websocket clients (one never reading); 0 to skip")
    p.add_argument("--core-only", action="store_true",
                   help="only the decoding paths (no service latency, no plug-in benchmarks)")
    p.set_defaults(func=cmd_bench)

    for name in PLUGIN_MODULES:
        if importlib.util.find_spec(name.rsplit(".", 1)[0]) is None or \
                importlib.util.find_spec(name) is None:
            continue
        importlib.import_module(name).add_subparser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except RadarIOError as exc:
        print(f"radar-io: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
