"""Radar simulator: RDR1 frames for a scripted flight (radar-interface.md §1–§4).

The aircraft flies straight legs at constant height (by default one straight
approach). The antenna lags the target by ``lag_s`` (a first-order servo in
steady tracking lags by velocity × time constant); the reported angle and range
words are the antenna's, and the servo-error words carry the difference plus
noise, so that servo-lag compensation (word + error) recovers the truth to the
quantisation and noise. NG dropouts clear RX_GOOD for a while, GO rises after
``go_delay_s``, and the camera shutter sets SYNC for ``sync_width_s`` every
``sync_every_s``. Optional corruption flips bits, drops and inserts bytes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from radar_io.coordinates.transforms import radar_sea
from radar_io.encoding.rdr1 import encode_frames, raw_words
from radar_io.wirespec.frame import FrameSpec, load_spec


@dataclass
class FlightScript:
    """A straight flight at constant height in the radar frame (X north, Y east, H up; m, deg).

    The default is a 15 km approach along the demo site's runway heading (340 deg)
    ending over its touchdown point, at 600 m above the antenna.
    """

    start_x_m: float = -14834.7
    start_y_m: float = 4122.4
    height_m: float = 600.0
    course_deg: float = 340.0
    speed_mps: float = 70.0
    length_m: float = 15000.0   #: flight length; the script repeats when looping

    def position(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """True X, Y, H (m) at flight times ``t_s`` (s since the start of the leg)."""
        c = math.radians(self.course_deg)
        d = self.speed_mps * np.asarray(t_s, dtype=np.float64)
        return (self.start_x_m + d * math.cos(c), self.start_y_m + d * math.sin(c),
                np.full(d.shape, self.height_m))

    @property
    def duration_s(self) -> float:
        return self.length_m / self.speed_mps


@dataclass
class SimConfig:
    """Simulator settings; times in seconds, rates per second."""

    rate_hz: float = 1000.0
    seed: int = 1
    lag_s: float = 0.05                 #: servo lag time constant
    noise_sr_m: float = 1.0             #: servo-error noise, 1 sigma
    noise_angle_deg: float = 0.005
    ng_per_min: float = 2.0             #: NG dropouts per minute (Poisson)
    ng_duration_s: float = 0.4
    go_delay_s: float = 1.0             #: GO = 0 for this long after the start
    sync_every_s: float = 5.0           #: camera shutter period (0 = never)
    sync_width_s: float = 0.02
    servo_bw: int = 2
    tod_start_s: float | None = None    #: radar time of day at start; default: now (UTC)
    flip_rate: float = 0.0              #: probability per byte of a flipped bit
    drop_rate: float = 0.0              #: probability per byte of being dropped
    insert_rate: float = 0.0            #: probability per byte of a random byte inserted after it
    loop: bool = False                  #: repeat the flight forever


@dataclass
class SimState:
    frame_index: int = 0
    ng_until: float = -1.0
    counts: dict[str, int] = field(default_factory=lambda: {"flipped": 0, "dropped": 0, "inserted": 0})


class RadarSimulator:
    """Generates the frames (and the truth) of a scripted flight, block by block."""

    def __init__(self, script: FlightScript | None = None, config: SimConfig | None = None,
                 spec: FrameSpec | None = None) -> None:
        self.script = script or FlightScript()
        self.cfg = cfg = config or SimConfig()
        if cfg.rate_hz <= 0:
            raise ValueError("rate_hz must be positive")
        self.spec = spec or load_spec()
        self.rng = np.random.default_rng(cfg.seed)
        self.state = SimState()
        #: radar time of day at frame 0 (s); the wall clock labels it when not configured
        self.tod_start_s = (cfg.tod_start_s if cfg.tod_start_s is not None
                            else time.time() % 86400.0)
        self._fs = {f.name: f for f in self.spec.fields}
        self._flag = {f.name: f for f in self.spec.flags}

    @property
    def finished(self) -> bool:
        return (not self.cfg.loop and
                self.state.frame_index / self.cfg.rate_hz >= self.script.duration_s)

    def generate(self, n: int) -> tuple[bytes, dict[str, np.ndarray]]:
        """The next ``n`` clean frames and their truth (``t_s``, ``x_m``, ``y_m``, ``h_m``, flags)."""
        cfg, st = self.cfg, self.state
        k = st.frame_index + np.arange(n)
        t = k / cfg.rate_hz
        tf = np.mod(t, self.script.duration_s) if cfg.loop else t
        x, y, h = self.script.position(tf)
        sr, el, az = radar_sea(x, y, h)
        xl, yl, hl = self.script.position(np.maximum(tf - cfg.lag_s, 0.0))
        sr_a, el_a, az_a = radar_sea(xl, yl, hl)  # where the antenna points
        rng = self.rng
        dsr = sr - sr_a + rng.normal(0, cfg.noise_sr_m, n)
        dele = el - el_a + rng.normal(0, cfg.noise_angle_deg, n)
        daz = (az - az_a + 180.0) % 360.0 - 180.0 + rng.normal(0, cfg.noise_angle_deg, n)
        # NG dropouts (Poisson arrivals, fixed length), carried across blocks
        p_start = cfg.ng_per_min / 60.0 / cfg.rate_hz
        start_t = np.where(rng.random(n) < p_start, t, -np.inf)
        last_start = np.maximum.accumulate(start_t)
        ng_until = np.maximum(last_start + cfg.ng_duration_s, st.ng_until)
        good = t >= ng_until
        st.ng_until = float(ng_until[-1]) if n else st.ng_until
        go = t >= cfg.go_delay_s
        sync = np.zeros(n, dtype=bool)
        if cfg.sync_every_s > 0:
            sync = np.mod(t, cfg.sync_every_s) < cfg.sync_width_s
            sync &= t >= cfg.sync_every_s  # first shutter one period after the start
        sts = np.zeros(n, dtype=np.int64)
        for name, val in (("sync", sync), ("rx_good", good), ("go", go),
                          ("auto", good), ("servo_bw", np.full(n, cfg.servo_bw))):
            fl = self._flag.get(name)
            if fl is not None:
                sts |= (np.asarray(val, dtype=np.int64) << fl.shift) & fl.mask
        # NG: the receiver has lost the target: errors read noise around zero
        dsr = np.where(good, dsr, rng.normal(0, 5.0, n))
        dele = np.where(good, dele, rng.normal(0, 0.1, n))
        daz = np.where(good, daz, rng.normal(0, 0.1, n))
        tod = np.mod(self.tod_start_s + t, 86400.0)
        el_w = np.where(el_a >= 180.0, el_a - 360.0, el_a)
        values = {"seq": k & 0xFFFF, "tod_s": tod, "sr_m": sr_a, "dsr_m": dsr,
                  "el_deg": el_w, "del_deg": dele, "az_deg": az_a % 360.0, "daz_deg": daz,
                  "status_raw": sts}
        # TOD is the time of day: round down, never up to 24 h
        tfield = self._fs["tod"]
        values["tod_s"] = np.floor(tod / tfield.lsb) * tfield.lsb
        raw = raw_words(self.spec, {f.column: values[f.column] for f in self.spec.fields})
        raw["az"] = raw["az"] & self._fs["az"].value_mask  # 360 deg wraps to 0
        st.frame_index += n
        truth = {"t_s": t, "x_m": x, "y_m": y, "h_m": h, "sr_m": sr, "el_deg": el, "az_deg": az,
                 "rx_good": good.astype(np.uint8), "go": go.astype(np.uint8),
                 "sync": sync.astype(np.uint8), "seq": (k & 0xFFFF)}
        return encode_frames(self.spec, raw), truth

    def corrupt(self, data: bytes) -> bytes:
        """Apply the configured bit flips, dropped and inserted bytes."""
        cfg = self.cfg
        if not (cfg.flip_rate or cfg.drop_rate or cfg.insert_rate):
            return data
        rng, counts = self.rng, self.state.counts
        b = np.frombuffer(data, dtype=np.uint8).copy()
        if cfg.flip_rate:
            i = np.flatnonzero(rng.random(b.size) < cfg.flip_rate)
            b[i] ^= (1 << rng.integers(0, 8, i.size)).astype(np.uint8)
            counts["flipped"] += int(i.size)
        keep = np.ones(b.size, dtype=bool)
        if cfg.drop_rate:
            keep = rng.random(b.size) >= cfg.drop_rate
            counts["dropped"] += int(b.size - keep.sum())
        if cfg.insert_rate:
            ins = np.flatnonzero(rng.random(b.size) < cfg.insert_rate)
            counts["inserted"] += int(ins.size)
            out = np.insert(b, ins + 1, rng.integers(0, 256, ins.size, dtype=np.uint8))
            mask = np.insert(keep, ins + 1, True)
            return out[mask].tobytes()
        return b[keep].tobytes()

    def stream(self, block_s: float = 0.02, duration_s: float | None = None,
               realtime: bool = False) -> Iterator[bytes]:
        """Corrupted (if configured) bytes in blocks of ``block_s``; paced to real time if asked."""
        per = max(1, round(block_s * self.cfg.rate_hz))
        total = None
        if duration_s is not None:
            total = round(duration_s * self.cfg.rate_hz)
        elif not self.cfg.loop:
            total = math.ceil(self.script.duration_s * self.cfg.rate_hz)
        start = time.monotonic()
        sent = 0
        while total is None or sent < total:
            n = per if total is None else min(per, total - sent)
            data, _ = self.generate(n)
            sent += n
            if realtime:
                due = start + sent / self.cfg.rate_hz
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            yield self.corrupt(data)
