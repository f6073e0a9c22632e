"""ASTERIX Category 048 (EUROCONTROL monoradar target reports) from measurement batches.

Written from the EUROCONTROL CAT048 specification (Part 4, edition 1.2x/1.3x UAP); no
PyPI package fitted (see docs/interchange.md). One record per *valid* sample
(RX_GOOD = 1 and GO = 1, finite compensated position), with the items

====  =========  ==========================================  =====================
FRN   item       content                                     scaling
====  =========  ==========================================  =====================
1     I048/010   SAC, SIC (site ``[asterix] sac, sic``)      u8, u8
2     I048/140   time of day (RDR1 TOD)                      u24, 1/128 s
3     I048/020   target report descriptor (one octet)        TYP=1 PSR, SIM, SPI=SYNC
4     I048/040   RHO = SR^ (compensated, calibrated)         u16, 1/256 NM
                 THETA = AZ^ from north                      u16, 360/2^16 deg
19    I048/110   3-D height H = SR^ sin(EL^) (above antenna)  i14, 25 ft
====  =========  ==========================================  =====================

FSPEC is therefore ``F1 01 08`` and every record is 15 bytes. A data block is
``CAT=48, LEN (u16, whole block), records…``; :meth:`Cat048Encoder.encode_blocks`
splits a batch into blocks of at most ``max_block_bytes``.
Values are rounded to the nearest LSB; RHO and the height saturate at their range
(counted in ``saturation``), THETA and the time of day wrap.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from radar_io.decoding.measurement import Columns
from radar_io.errors import ConfigError, EncodeError

CATEGORY = 48
NM_M = 1852.0                     #: one nautical mile, metres
FT_M = 0.3048                     #: one foot, metres
RHO_LSB_M = NM_M / 256.0          #: I048/040 RHO LSB
THETA_LSB_DEG = 360.0 / 65536.0   #: I048/040 THETA LSB
TOD_LSB_S = 1.0 / 128.0           #: I048/140 LSB
DAY_COUNTS = 86400 * 128          #: I048/140 wraps at midnight
HEIGHT_LSB_M = 25.0 * FT_M        #: I048/110 LSB
FSPEC = bytes((0xF1, 0x01, 0x08))  # FRN 1-4 + FX, FX, FRN 19
RECORD_BYTES = len(FSPEC) + 2 + 3 + 1 + 4 + 2
#: TYP values of I048/020 (3 bits)
TYP_PSR = 1
REQUIRED_COLUMNS = ("tod_s", "rx_good", "go", "sr_c_m", "az_c_deg", "h_m")
#: one ASTERIX data block per Ethernet frame's UDP payload (1500 - 20 - 8)
DEFAULT_BLOCK_BYTES = 1472


def check_code(name: str, value: Any, where: str = "") -> int:
    """A SAC or SIC: an integer 0–255; ConfigError in one line otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
            or not 0 <= int(value) <= 255:
        raise ConfigError(f"{where or 'asterix'}: {name} = {value!r} must be an integer 0 .. 255")
    return int(value)


class Cat048Encoder:
    """Streaming CAT048 encoder: batch columns → records / data blocks (vectorised).

    ``sac``, ``sic``: data source identifier; ``simulated`` sets I048/020 SIM;
    ``spi_from_sync`` sets SPI on samples whose SYNC bit is 1 (the airborne event
    contact); ``require_go``: only GO = 1 samples are reports (as the TLM1 uplink).
    """

    def __init__(self, sac: int = 0, sic: int = 0, *, simulated: bool = False,
                 spi_from_sync: bool = True, require_go: bool = True,
                 max_block_bytes: int = DEFAULT_BLOCK_BYTES) -> None:
        self.sac, self.sic = check_code("sac", sac), check_code("sic", sic)
        if not RECORD_BYTES + 3 <= max_block_bytes <= 65535:
            raise ConfigError(f"asterix: max_block_bytes = {max_block_bytes} must be "
                              f"{RECORD_BYTES + 3} .. 65535")
        self.simulated, self.spi_from_sync, self.require_go = simulated, spi_from_sync, require_go
        self.max_block_bytes = max_block_bytes
        self.records = 0
        self.blocks = 0
        self.saturation = {"rho": 0, "height": 0}

    @classmethod
    def for_site(cls, site: Any, **options: Any) -> Cat048Encoder:
        """SAC/SIC from the site (``Site.asterix_sac/asterix_sic``; 0 when absent)."""
        where = f"site {getattr(site, 'name', '?')} [asterix]"
        return cls(check_code("sac", getattr(site, "asterix_sac", 0) or 0, where),
                   check_code("sic", getattr(site, "asterix_sic", 0) or 0, where), **options)

    # -------------------------------------------------------------------- records
    def valid(self, cols: Columns) -> np.ndarray:
        """Mask of the samples that become reports."""
        missing = [c for c in REQUIRED_COLUMNS if c not in cols]
        if missing:
            raise EncodeError(f"ASTERIX CAT048 needs column(s) {', '.join(missing)}"
                              + (" (decode with --site for h_m)" if "h_m" in missing else ""))
        ok = np.asarray(cols["rx_good"]) == 1
        if self.require_go:
            ok &= np.asarray(cols["go"]) == 1
        for c in ("sr_c_m", "az_c_deg", "h_m", "tod_s"):
            ok &= np.isfinite(np.asarray(cols[c], dtype=np.float64))
        return ok

    def records_array(self, cols: Columns) -> np.ndarray:
        """(n, 15) uint8: one CAT048 record per valid sample, in row order."""
        ok = self.valid(cols)
        n = int(ok.sum())
        out = np.empty((n, RECORD_BYTES), dtype=np.uint8)
        if n == 0:
            return out
        f64 = lambda c: np.asarray(cols[c], dtype=np.float64)[ok]  # noqa: E731
        out[:, 0:3] = np.frombuffer(FSPEC, dtype=np.uint8)
        out[:, 3], out[:, 4] = self.sac, self.sic
        tod = np.rint(f64("tod_s") / TOD_LSB_S).astype(np.int64) % DAY_COUNTS
        _put_be(out, 5, 3, tod)
        trd = np.full(n, TYP_PSR << 5, dtype=np.int64)
        if self.simulated:
            trd |= 0x10
        if self.spi_from_sync and "sync" in cols:
            trd |= (np.asarray(cols["sync"])[ok].astype(np.int64) & 1) << 2
        out[:, 8] = trd
        rho = np.rint(f64("sr_c_m") / RHO_LSB_M)
        over = (rho < 0) | (rho > 0xFFFF)
        self.saturation["rho"] += int(over.sum())
        _put_be(out, 9, 2, np.clip(rho, 0, 0xFFFF).astype(np.int64))
        theta = np.rint(f64("az_c_deg") / THETA_LSB_DEG).astype(np.int64) & 0xFFFF
        _put_be(out, 11, 2, theta)
        h = np.rint(f64("h_m") / HEIGHT_LSB_M)
        over = np.abs(h) > 8191
        self.saturation["height"] += int(over.sum())
        _put_be(out, 13, 2, np.clip(h, -8192, 8191).astype(np.int64) & 0x3FFF)
        self.records += n
        return out

    # -------------------------------------------------------------------- blocks
    def encode_blocks(self, cols: Columns) -> list[bytes]:
        """Data blocks (CAT, LEN, records) of at most ``max_block_bytes`` each."""
        recs = self.records_array(cols)
        per = (self.max_block_bytes - 3) // RECORD_BYTES
        blocks = []
        for k in range(0, len(recs), per):
            body = recs[k:k + per].tobytes()
            blocks.append(bytes((CATEGORY,)) + (len(body) + 3).to_bytes(2, "big") + body)
        self.blocks += len(blocks)
        return blocks

    def encode_batch(self, cols: Columns) -> bytes:
        """Concatenated data blocks of one batch (the ``.ast`` file format)."""
        return b"".join(self.encode_blocks(cols))


def _put_be(out: np.ndarray, at: int, size: int, values: np.ndarray) -> None:
    """Write ``values`` big-endian into bytes ``at … at+size-1`` of every row."""
    for k in range(size):
        out[:, at + k] = (values >> (8 * (size - 1 - k))) & 0xFF


def decode_records(data: bytes) -> dict[str, np.ndarray]:
    """Our own reader of the blocks this module writes (fixed FSPEC ``F1 01 08``), for checks
    and round trips: SAC, SIC, tod_s, typ, sim, spi, sr_m, az_deg, h_m. EncodeError names the
    offset of anything else."""
    recs = []
    pos = 0
    while pos < len(data):
        if pos + 3 > len(data):
            raise EncodeError(f"ASTERIX: truncated block header at byte {pos}")
        cat, length = data[pos], int.from_bytes(data[pos + 1:pos + 3], "big")
        if cat != CATEGORY or length < 3 or pos + length > len(data) \
                or (length - 3) % RECORD_BYTES:
            raise EncodeError(f"ASTERIX: block at byte {pos}: CAT {cat}, LEN {length} "
                              "is not a CAT048 block of this encoder")
        recs.append(np.frombuffer(data, np.uint8, length - 3, pos + 3)
                    .reshape(-1, RECORD_BYTES))
        pos += length
    r = np.concatenate(recs) if recs else np.empty((0, RECORD_BYTES), np.uint8)
    if len(r) and not (r[:, 0:3] == np.frombuffer(FSPEC, np.uint8)).all():
        raise EncodeError("ASTERIX: a record's FSPEC is not F1 01 08")
    be = lambda a, s: sum(r[:, a + k].astype(np.int64) << (8 * (s - 1 - k))  # noqa: E731
                          for k in range(s))
    h = be(13, 2) & 0x3FFF
    h = np.where(h >= 0x2000, h - 0x4000, h)
    return {"sac": r[:, 3].astype(np.int64), "sic": r[:, 4].astype(np.int64),
            "tod_s": be(5, 3) * TOD_LSB_S, "typ": r[:, 8] >> 5, "sim": (r[:, 8] >> 4) & 1,
            "spi": (r[:, 8] >> 2) & 1, "sr_m": be(9, 2) * RHO_LSB_M,
            "az_deg": be(11, 2) * THETA_LSB_DEG, "h_m": h * HEIGHT_LSB_M}


def write_asterix(batches: Iterable[Columns], path: str, *,
                  site: Any = None, encoder: Cat048Encoder | None = None) -> Cat048Encoder:
    """Write concatenated CAT048 data blocks of every batch to ``path`` (``OUT.ast``; the file
    appears only when complete); returns the encoder (``records``, ``blocks``, ``saturation``)."""
    from radar_io.sinks.asterix import AsterixFileWriter

    enc = encoder or (Cat048Encoder.for_site(site) if site is not None else Cat048Encoder())
    with AsterixFileWriter(path, encoder=enc) as sink:
        for b in batches:
            sink.write(b)
    return enc
