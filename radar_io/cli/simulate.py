"""``radar-io simulate``: synthesise RDR1 frames for a scripted flight."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from radar_io.cli.common import load_common
from radar_io.errors import ConfigError


def add_subparser(sub: Any) -> None:
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
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
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
    sim = RadarSimulator(script, cfg, load_common(args)["spec"])
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
            f = open(target, "wb")  # noqa: SIM115 - closed by close() after the stream
        except OSError as exc:
            raise ConfigError(f"cannot write {target}: {exc.strerror}") from exc
        write, close = f.write, f.close
    from radar_io.cli.progress import Progress

    total = args.duration_s if args.duration_s is not None else script.duration_s
    progress = Progress("simulate", total=int(total * args.rate_hz),
                        enabled=not args.quiet and target != "-", unit="kframes", scale=1e-3)
    t0 = time.monotonic()
    try:
        for data in sim.stream(block_s=0.02, duration_s=args.duration_s, realtime=realtime):
            write(data)
            progress.update(sim.state.frame_index)
    except BrokenPipeError:
        return 0
    finally:
        close()
    if target != "-":
        progress.close(f"{sim.state.frame_index} frames in {time.monotonic() - t0:.1f} s"
                       f" to {target}; corruption {sim.state.counts}")
    return 0
