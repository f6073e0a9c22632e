"""``radar-io doctor``: is this computer ready to receive the radar?

Each check prints one line ``OK|WARN|FAIL  name: finding`` and, unless OK, a
``fix:`` line with one thing to do. Exit code 1 when any check FAILs, else 0.

Checks: serial ports (pyserial ``list_ports``) with the FTDI latency timer
(``/sys/bus/usb-serial/devices/*/latency_timer``, ms), permission to open the
source's device (``dialout`` group), free space in the data directory, whether
the configured source opens and RDR1 frames arrive within ``--timeout-s``, and
clock synchronisation (``timedatectl show``, ``/run/systemd/timesync``, ``chronyc``).
"""

from __future__ import annotations

import argparse
import grp
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: data-directory free space below which the check FAILs / WARNs (bytes)
FAIL_FREE_BYTES = 1 << 30
WARN_FREE_BYTES = 10 << 30
#: sysfs root for the USB-serial devices (a parameter for tests)
USB_SERIAL_SYSFS = "/sys/bus/usb-serial/devices"


@dataclass
class Check:
    """One doctor finding."""

    level: str   #: OK, WARN or FAIL
    name: str
    message: str
    fix: str = ""

    def lines(self) -> list[str]:
        out = [f"{self.level:<4}  {self.name}: {self.message}"]
        if self.level != "OK" and self.fix:
            out.append(f"      fix: {self.fix}")
        return out


def check_serial_ports(sysfs: str = USB_SERIAL_SYSFS) -> list[Check]:
    """One line per serial port; FTDI ports with their latency timer (1 ms wanted)."""
    from serial.tools import list_ports

    ports = list(list_ports.comports())
    if not ports:
        return [Check("WARN", "serial ports", "no serial ports found",
                      "plug in the radar's USB-serial adapter (check `dmesg | tail`)")]
    out = []
    for p in ports:
        name = os.path.basename(p.device)
        desc = f"{p.device} ({p.description}; {p.hwid})"
        lt = Path(sysfs) / name / "latency_timer"
        if lt.is_file():
            try:
                ms = int(lt.read_text().strip())
            except (OSError, ValueError):
                out.append(Check("WARN", "serial port", f"{desc}: latency timer unreadable",
                                 f"cat {lt}"))
                continue
            if ms > 1:
                out.append(Check("WARN", "serial port", f"{desc}: FTDI latency timer {ms} ms "
                                 "(frames arrive in 16 ms bursts)",
                                 f"echo 1 | sudo tee {lt}  (or a udev rule: ATTR{{latency_timer}}=\"1\")"))
            else:
                out.append(Check("OK", "serial port", f"{desc}: FTDI latency timer {ms} ms"))
        else:
            out.append(Check("OK", "serial port", desc))
    return out


def _device_of(url: str) -> str | None:
    """The device path of a serial source URL, or None (sim://, socket://, …)."""
    from radar_io.sources import scheme_of

    if scheme_of(url) or "://" in url:
        return None
    return url.split("?", 1)[0]


def check_permission(url: str) -> Check:
    """Whether this user may open the source's device (the ``dialout`` group)."""
    dev = _device_of(url)
    try:
        groups = {grp.getgrgid(g).gr_name for g in os.getgroups()}
    except KeyError:
        groups = set()
    user = os.environ.get("USER") or str(os.getuid())
    if dev is None:
        return Check("OK", "permission", f"source {url} needs no device permission")
    if not os.path.exists(dev):
        if os.geteuid() == 0 or "dialout" in groups:
            return Check("OK", "permission", f"{dev} absent; user {user} may open serial ports "
                         "(root or group dialout)")
        return Check("WARN", "permission", f"{dev} absent; user {user} is not in group dialout",
                     f"sudo usermod -aG dialout {user}  (then log in again)")
    if os.access(dev, os.R_OK | os.W_OK):
        return Check("OK", "permission", f"{dev} is readable and writable")
    return Check("FAIL", "permission", f"{dev}: permission denied for user {user}",
                 f"sudo usermod -aG dialout {user}  (then log in again)")


def check_disk(data_dir: str) -> Check:
    """Free space where recordings go (the nearest existing parent if it is not made yet)."""
    p = Path(data_dir).resolve()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        free = shutil.disk_usage(p).free
    except OSError as exc:
        return Check("FAIL", "disk", f"{data_dir}: {exc.strerror}", "create the data directory")
    # one RDR1 stream at 1 kHz of 24-byte frames ≈ 86 MB per hour
    hours = free / (24 * 1000 * 3600)
    msg = f"{data_dir}: {free / 1e9:.1f} GB free (≈ {hours:.0f} h of recording at 1 kHz)"
    fix = f"free space on the disk holding {p} or set data_dir to a larger disk"
    if free < FAIL_FREE_BYTES:
        return Check("FAIL", "disk", msg, fix)
    if free < WARN_FREE_BYTES:
        return Check("WARN", "disk", msg, fix)
    return Check("OK", "disk", msg)


def check_source(url: str, timeout_s: float = 3.0, spec: Any = None) -> Check:
    """Open the source and read until an RDR1 frame passes the framer or ``timeout_s`` ends."""
    from radar_io.errors import RadarIOError
    from radar_io.framing.core import BatchFramer
    from radar_io.sources import open_source
    from radar_io.wirespec.frame import load_spec

    spec = spec or load_spec()
    try:
        src = open_source(url)
        src.open()
    except RadarIOError as exc:
        dev = _device_of(url)
        fix = ("check the cable and the device name (ls /dev/ttyUSB* /dev/serial/by-id/); "
               "set source in the config" if dev else "check the source URL")
        return Check("FAIL", "source", f"cannot open {url}: {exc}", fix)
    framer = BatchFramer(spec)
    nbytes = 0
    t_end = time.monotonic() + timeout_s
    try:
        while time.monotonic() < t_end:
            try:
                data = src.read(min(0.2, max(0.01, t_end - time.monotonic())))
            except RadarIOError as exc:
                return Check("FAIL", "source", f"{url} failed while reading: {exc}",
                             "check the cable and that nothing else holds the port")
            if data:
                nbytes += len(data)
                framer.feed_blocks(data)
                if framer.stats.frames:
                    st = framer.stats
                    return Check("OK", "source", f"{url}: {st.frames} frames in {nbytes} bytes "
                                 f"(CRC errors {st.crc_errors})")
    finally:
        src.close()
    if nbytes:
        return Check("FAIL", "source", f"{url}: {nbytes} bytes in {timeout_s:g} s but no valid "
                     f"RDR1 frame (CRC errors {framer.stats.crc_errors})",
                     "check the baud rate (?baudrate=…) and the frame spec")
    return Check("FAIL", "source", f"{url}: opened, no bytes in {timeout_s:g} s",
                 "check that the radar is on and transmitting, and the cable/baud rate")


def check_clock() -> Check:
    """Clock synchronisation (NTP/PTP) by whichever tool this system has."""
    from radar_io.service.clock import clock_sync_state

    fix = "enable time sync: sudo timedatectl set-ntp true (or install chrony)"
    sync, how = clock_sync_state()
    if sync:
        return Check("OK", "clock", f"synchronised ({how})")
    if sync is None:
        return Check("WARN", "clock", f"cannot tell: {how}", fix)
    return Check("WARN", "clock", f"not synchronised ({how})", fix)


def default_source() -> str:
    """The first serial port found, else /dev/ttyUSB0 (the usual FTDI adapter)."""
    from serial.tools import list_ports

    ports = sorted(p.device for p in list_ports.comports())
    return ports[0] if ports else "/dev/ttyUSB0"


def run_checks(source: str, data_dir: str, timeout_s: float = 3.0,
               sysfs: str = USB_SERIAL_SYSFS) -> list[Check]:
    return [*check_serial_ports(sysfs), check_permission(source), check_disk(data_dir),
            check_source(source, timeout_s), check_clock()]


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("doctor", help="check serial ports, permissions, disk, source and clock",
                       description="Field-setup checks, one line each (OK / WARN / FAIL) with "
                       "a one-line fix; exits 1 when any check fails.")
    p.add_argument("--config", metavar="CONFIG.toml", help="service config: source and data_dir")
    p.add_argument("--source", help="source to try (default: the config's, else the first "
                   "serial port, else /dev/ttyUSB0)")
    p.add_argument("--data-dir", help="data directory (default: the config's, else ./radar-data)")
    p.add_argument("--timeout-s", type=float, default=3.0, help="wait this long for frames")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    source, data_dir = args.source, args.data_dir
    if args.config:
        from radar_io.service.config import load_config

        cfg = load_config(args.config, {})
        source = source or cfg.source
        data_dir = data_dir or cfg.data_dir
    source = source or default_source()
    data_dir = data_dir or "radar-data"
    checks = run_checks(source, data_dir, args.timeout_s)
    for c in checks:
        for line in c.lines():
            print(line)
    fails = sum(c.level == "FAIL" for c in checks)
    warns = sum(c.level == "WARN" for c in checks)
    print(f"doctor: {len(checks)} checks, {fails} FAIL, {warns} WARN", file=sys.stderr)
    return 1 if fails else 0
