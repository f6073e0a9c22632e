"""``radar-io monitor``: a live line in the terminal from any source."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from radar_io.cli.common import add_common, load_common


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("monitor", help="live table of a source in the terminal",
                       description="Read a source, decode frame by frame and show a live line.")
    p.add_argument("--source", default="sim://", help="sim:// (default), serial URL or replay://")
    p.add_argument("--duration-s", type=float, help="stop after this many seconds")
    add_common(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.decoding.frame_decoder import FrameDecoder
    from radar_io.framing.core import Framer
    from radar_io.sources import open_source
    from radar_io.sources.reconnect import ReconnectingSource

    common = load_common(args)
    src = ReconnectingSource(open_source(args.source))
    framer = Framer(common["spec"])
    dec = FrameDecoder(common["spec"], common["calibration"], common["site"])
    t_end = time.monotonic() + args.duration_s if args.duration_s else None
    last: dict[str, Any] | None = None
    t_print = 0.0
    n_rate, t_rate, rate = 0, time.monotonic(), 0.0
    tty = sys.stdout.isatty()
    try:
        while t_end is None or time.monotonic() < t_end:
            was_connected = src.connected
            data = src.read(0.1)
            if was_connected and not src.connected:
                print(f"\nradar-io monitor: {src.last_error}; reconnecting", file=sys.stderr)
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
