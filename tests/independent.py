"""An RDR1 encoder/decoder written from radar-interface.md §1–§3 by hand.

Deliberately independent of radar_io: the layout, LSBs and bit masks are typed
in here from the markdown spec, not read from firmware_specs/, and the CRC is
binascii's. Tests use it as the outside reference.
"""

from __future__ import annotations

import binascii
import math
import struct

LAYOUT = struct.Struct(">HHIHHHHHHH")  # sync, seq, tod, sr, dsr, el, del, az, daz, sts
SYNC = 0xEB90


def frame(seq: int = 0, tod: int = 0, sr: int = 0, dsr: int = 0x800, el: int = 0, dele: int = 0x800,
          az: int = 0, daz: int = 0x800, sts: int = 0, crc: int | None = None) -> bytes:
    """Raw words → 24 frame bytes. ``el`` may be negative (two's complement)."""
    body = LAYOUT.pack(SYNC, seq & 0xFFFF, tod, sr, dsr, el & 0xFFFF, dele, az, daz, sts)
    c = binascii.crc_hqx(body, 0xFFFF) if crc is None else crc
    return body + struct.pack(">H", c)


def decode(fr: bytes) -> dict:
    """Expected decoding of one frame per the markdown spec (zero calibration bias)."""
    _, seq, tod, sr, dsr, el, dele, az, daz, sts = LAYOUT.unpack(fr[:22])
    el_s = el - 65536 if el >= 32768 else el
    d = {
        "seq": seq, "tod_s": tod * 1e-4, "sr_m": float(sr),
        "dsr_m": (dsr - 2048) * 50.0 / 2048, "el_deg": el_s * 180.0 / 32768,
        "del_deg": (dele - 2048) / 2048.0, "az_deg": az * 180.0 / 32768,
        "daz_deg": (daz - 2048) / 2048.0,
        "sync": (sts >> 15) & 1, "auto": (sts >> 14) & 1, "servo_bw": (sts >> 12) & 3,
        "rx_good": (sts >> 2) & 1, "go": sts & 1, "status_raw": sts,
    }
    if d["rx_good"]:
        s = d["sr_m"] + d["dsr_m"]
        e = d["el_deg"] + d["del_deg"]
        a = (d["az_deg"] + d["daz_deg"]) % 360.0
        d.update(sr_c_m=s, el_c_deg=e, az_c_deg=a,
                 x_m=s * math.cos(math.radians(e)) * math.cos(math.radians(a)),
                 y_m=s * math.cos(math.radians(e)) * math.sin(math.radians(a)),
                 h_m=s * math.sin(math.radians(e)))
    else:
        d.update(dict.fromkeys(("sr_c_m", "el_c_deg", "az_c_deg", "x_m", "y_m", "h_m")))
    return d
