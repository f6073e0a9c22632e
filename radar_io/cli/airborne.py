"""``radar-io can-log`` and ``radar-io align``: the airborne recorder on the command line.

One of the commands of ``radar_io.cli.main`` (``add_subparser``).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from radar_io.cli.argtypes import finite_float as _finite
from radar_io.cli.argtypes import positive_float as _positive
from radar_io.errors import AirborneError


def cmd_can_log(args: argparse.Namespace) -> int:
    from radar_io.sources.canbus import CanRecorder, open_bus

    bus = open_bus(args.interface, args.channel, args.bitrate)
    tx = None
    try:
        with CanRecorder(bus, args.output) as rec:
            if args.simulate:
                tx = open_bus(args.interface, args.channel, args.bitrate)
                _simulate(args, tx, rec)
            else:
                rec.run(args.duration_s)
    finally:
        bus.shutdown()
        if tx is not None:
            tx.shutdown()
    if not args.quiet:
        print(f"can-log: {rec.messages} messages to {args.output}", file=sys.stderr)
    return 0


def _simulate(args: argparse.Namespace, tx: Any, rec: Any) -> None:
    """Put a simulated flight's recorder traffic on the bus (as fast as it is recorded)."""
    from radar_io.simulation.aircraft import AircraftConfig, AircraftSimulator
    from radar_io.simulation.radar import FlightScript, SimConfig

    script = FlightScript(**{k: getattr(args, k) for k in FlightScript.__dataclass_fields__
                             if getattr(args, k) is not None})
    radar = SimConfig(sync_every_s=args.sync_every_s, loop=args.duration_s is not None)
    cfg = AircraftConfig(clock_offset_s=args.clock_offset_s, drift_ppm=args.drift_ppm,
                         qnh_hpa=args.qnh_hpa, antenna_msl_m=args.antenna_msl_m)
    sim = AircraftSimulator(script, radar, cfg, duration_s=args.duration_s)
    t, block = 0.0, 0.5
    while t < sim.duration_s:
        sim.send(tx, t, min(t + block, sim.duration_s))
        t += block
        rec.drain(0.0)
    while rec.drain(0.2):   # the last messages in flight
        pass


def cmd_align(args: argparse.Namespace) -> int:
    from radar_io.analysis.clock_alignment import align_files

    if (args.antenna_msl_m is None) != (args.qnh_hpa is None):
        raise AirborneError("give both --antenna-msl-m and --qnh-hpa for the expected difference")
    spec = None
    if args.spec:
        from radar_io.wirespec.frame import load_spec

        spec = load_spec(args.spec)
    doc = align_files(args.radar, args.aircraft, dbc=args.dbc, drift=not args.no_drift,
                      max_lag=args.max_lag, antenna_msl_m=args.antenna_msl_m,
                      qnh_hpa=args.qnh_hpa, spec=spec)
    print(json.dumps(doc, indent=2))
    return 0


def add_subparser(subparsers: Any) -> None:
    """Add ``can-log`` and ``align`` to ``radar-io``."""
    p = subparsers.add_parser(
        "can-log", help="record the airborne recorder's CAN traffic to a python-can log",
        description="Record every CAN message on an interface to a python-can log file "
        "(.asc, .blf, .log, .csv, .trc by extension). With --simulate, also put a simulated "
        "flight's recorder traffic on the bus (the flight of `radar-io simulate` with the same "
        "options; shutter every --sync-every-s), faster than real time; --duration-s is then "
        "simulated time.")
    p.add_argument("--interface", required=True, help="python-can interface: socketcan, pcan, virtual, …")
    p.add_argument("--channel", required=True, help="channel of the interface: can0, PCAN_USBBUS1, …")
    p.add_argument("--bitrate", type=int, help="bit rate (interfaces that need one)")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="log file (.asc, .blf, .log, …)")
    p.add_argument("--duration-s", type=_positive, help="stop after this long (default: Ctrl-C, or "
                   "with --simulate one approach)")
    p.add_argument("-q", "--quiet", action="store_true")
    s = p.add_argument_group("simulation")
    s.add_argument("--simulate", action="store_true", help="run the aircraft simulator on the bus")
    s.add_argument("--sync-every-s", type=_positive, default=5.0, help="camera shutter period")
    for name, what in (("start-x-m", "start, metres north of the radar"),
                       ("start-y-m", "start, metres east of the radar"),
                       ("height-m", "height above the antenna"), ("course-deg", "true course"),
                       ("speed-mps", "ground speed"), ("length-m", "flight length")):
        s.add_argument(f"--{name}", type=_positive if name in ("speed-mps", "length-m") else _finite,
                       help=f"{what} (as for radar-io simulate)")
    s.add_argument("--clock-offset-s", type=_finite, default=5000.0, help="DAU clock at the start")
    s.add_argument("--drift-ppm", type=_finite, default=0.0, help="DAU clock rate error")
    s.add_argument("--qnh-hpa", type=_positive, default=1003.0)
    s.add_argument("--antenna-msl-m", type=_finite, default=12.0, help="antenna height above MSL")
    p.set_defaults(func=cmd_can_log)

    a = subparsers.add_parser(
        "align", help="align an airborne CAN log to a radar recording (JSON)",
        description="Match the aircraft's shutter events to the radar's SYNC 0->1 edges, fit the "
        "clock offset and drift, and compare the aligned pressure altitude with the radar height.")
    a.add_argument("radar", metavar="RADAR.rdrlog", help="radar recording (or raw capture)")
    a.add_argument("aircraft", metavar="AIRCRAFT.log", help="python-can log of the recorder traffic")
    a.add_argument("--dbc", help="DBC file (default firmware_specs/airdata.dbc)")
    a.add_argument("--spec", help="radar frame spec TOML (default firmware_specs/rdr1.toml)")
    a.add_argument("--no-drift", action="store_true", help="fit the clock offset only")
    a.add_argument("--max-lag", type=int, default=2, help="events either recorder may have missed at an end")
    a.add_argument("--antenna-msl-m", type=_finite, help="antenna height above MSL (expected difference)")
    a.add_argument("--qnh-hpa", type=_positive, help="QNH during the flight (expected difference)")
    a.set_defaults(func=cmd_align)
