"""Aircraft simulator: the airborne recorder's CAN traffic for the radar simulator's flight.

The aircraft flies the same :class:`~radar_io.simulation.radar.FlightScript` as the
radar simulator (``t`` = simulation time, the radar simulator's ``t_s``; the
radar's TOD is ``tod_start_s + t``). Its data acquisition unit (DAU) has its own
clock, ``T = clock_offset_s + (1 + drift_ppm·1e-6)·t``, samples the air data
whenever ``T`` is a multiple of 1/8 s and time-stamps each camera-shutter
closure. The shutter instants are those of the radar's SYNC 0→1 edges: by
default ``k·sync_every_s`` for k ≥ 1 (the radar simulator's schedule).

Pressure altitude (ISA, 1013.25 hPa datum) differs from the radar height H
(above the antenna, on the antenna's tangent plane) by::

    PA - H = altitude_msl - H + qnh_height(QNH)
    altitude_msl = sqrt(d² + (R + a + H)²) - R  ≈ a + H + d²/(2R)

with ``a`` the antenna's height above MSL, ``d`` the horizontal range, R the
earth radius and ``qnh_height(QNH)`` the ISA pressure altitude of the QNH level
(≈ +8.3 m per hPa below 1013.25). The atmosphere is ISA-temperature, so there
is no temperature error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from radar_io.decoding.airdata import load_dbc
from radar_io.simulation.radar import FlightScript, SimConfig

R_EARTH_M = 6_371_000.0
FT_M = 0.3048
KT_MPS = 1852.0 / 3600.0
NM_M = 1852.0


def qnh_height_m(qnh_hpa: float) -> float:
    """ISA pressure altitude (m) of the pressure level ``qnh_hpa``: the QNH level's PA."""
    return 44330.77 * (1.0 - (qnh_hpa / 1013.25) ** 0.190263)


def altitude_msl_m(x_m: Any, y_m: Any, h_m: Any, antenna_msl_m: float) -> Any:
    """Height above mean sea level (spherical earth) of a radar-frame position."""
    d2 = np.square(x_m) + np.square(y_m)
    return np.sqrt(d2 + np.square(R_EARTH_M + antenna_msl_m + np.asarray(h_m))) - R_EARTH_M


def expected_pa_minus_h(x_m: Any, y_m: Any, h_m: Any, antenna_msl_m: float, qnh_hpa: float) -> Any:
    """Expected pressure altitude minus radar height H (m), see the module docstring."""
    return altitude_msl_m(x_m, y_m, h_m, antenna_msl_m) - np.asarray(h_m) + qnh_height_m(qnh_hpa)


@dataclass
class AircraftConfig:
    """Aircraft and DAU settings (radar frame positions in metres)."""

    clock_offset_s: float = 5000.0      #: DAU clock at simulation time 0
    drift_ppm: float = 0.0              #: DAU clock rate error (+ = fast)
    sample_rate_hz: float = 8.0
    antenna_msl_m: float = 12.0         #: radar antenna height above mean sea level
    qnh_hpa: float = 1003.0
    aoa_deg: float = 2.5                #: pitch in level flight
    dme1_xyh_m: tuple[float, float, float] = (-20000.0, 3000.0, 40.0)
    dme2_xyh_m: tuple[float, float, float] = (5000.0, -15000.0, 120.0)
    shutter_count_start: int = 0        #: events before the simulation starts


class AircraftSimulator:
    """CAN messages of the air data and shutter events for a simulated flight."""

    def __init__(self, script: FlightScript | None = None, radar: SimConfig | None = None,
                 config: AircraftConfig | None = None, *, duration_s: float | None = None,
                 shutter_times_s: Any = None, db: Any = None) -> None:
        self.script = script or FlightScript()
        self.radar = radar or SimConfig()
        self.cfg = cfg = config or AircraftConfig()
        self.duration_s = self.script.duration_s if duration_s is None else float(duration_s)
        self.db = db if db is not None else load_dbc()
        if shutter_times_s is None:
            p = self.radar.sync_every_s
            k = np.arange(1, int(self.duration_s / p) + 2) if p > 0 else np.empty(0)
            shutter_times_s = k * p
        st = np.asarray(shutter_times_s, dtype=np.float64)
        self.shutter_times_s = st[(st >= 0) & (st < self.duration_s)]
        self.rate = 1.0 + cfg.drift_ppm * 1e-6
        # sample k of the DAU is taken at DAU time k / sample_rate_hz
        k0 = math.ceil(cfg.clock_offset_s * cfg.sample_rate_hz)
        k1 = math.ceil(self.dau_time(self.duration_s) * cfg.sample_rate_hz)
        self.sample_k = np.arange(k0, k1)
        self.sample_t = self.sim_time(self.sample_k / cfg.sample_rate_hz)
        self._msg = {n: self.db.get_message_by_name(n) for n in
                     ("SHUTTER_EVENT", "AIR_DATA_TIME", "AIR_DATA_1", "ATTITUDE", "DME")}

    def dau_time(self, t: Any) -> Any:
        """DAU clock (s) at simulation time ``t``."""
        return self.cfg.clock_offset_s + self.rate * np.asarray(t, dtype=np.float64)

    def sim_time(self, dau_s: Any) -> Any:
        return (np.asarray(dau_s, dtype=np.float64) - self.cfg.clock_offset_s) / self.rate

    def air_data(self, t: Any) -> dict[str, np.ndarray]:
        """True air data at simulation times ``t`` (engineering units of the DBC)."""
        s, cfg = self.script, self.cfg
        t = np.asarray(t, dtype=np.float64)
        tf = np.mod(t, s.duration_s) if self.radar.loop else t
        x, y, h = s.position(tf)
        pa_m = altitude_msl_m(x, y, h, cfg.antenna_msl_m) + qnh_height_m(cfg.qnh_hpa)
        sigma = (1.0 - 2.25577e-5 * pa_m) ** 4.2559     # ISA density ratio
        ones = np.ones_like(t)

        def dme(st: tuple[float, float, float]) -> np.ndarray:
            return np.sqrt((x - st[0]) ** 2 + (y - st[1]) ** 2 + (h - st[2]) ** 2) / NM_M

        return {"x_m": x, "y_m": y, "h_m": h, "PressureAltitude": pa_m / FT_M,
                "IAS": s.speed_mps * np.sqrt(sigma) / KT_MPS, "Pitch": cfg.aoa_deg * ones,
                "Roll": 0.0 * ones, "Heading": (s.course_deg % 360.0) * ones,
                "DME1Range": dme(cfg.dme1_xyh_m), "DME2Range": dme(cfg.dme2_xyh_m)}

    def messages(self, t0: float, t1: float) -> list[Any]:
        """The messages due in simulation time [t0, t1), in time order (a shutter event first on ties)."""
        import can

        def mk(name: str, sig: dict[str, float], scaling: bool = True) -> Any:
            m = self._msg[name]
            return can.Message(arbitration_id=m.frame_id, is_extended_id=False,
                               data=m.encode(sig, scaling=scaling))

        out: list[tuple[float, int, Any]] = []
        ev = np.flatnonzero((self.shutter_times_s >= t0) & (self.shutter_times_s < t1))
        for i in ev.tolist():
            t = float(self.shutter_times_s[i])
            raw_t = round(float(self.dau_time(t)) * 1e4)
            out.append((t, 0, mk("SHUTTER_EVENT", {"ShutterCount": self._count(i + 1),
                                                   "ShutterTime": raw_t & 0xFFFFFFFF}, False)))
        sel = np.flatnonzero((self.sample_t >= t0) & (self.sample_t < t1))
        if sel.size:
            ad = self.air_data(self.sample_t[sel])
            for j, i in enumerate(sel.tolist()):
                t, k = float(self.sample_t[i]), int(self.sample_k[i])
                cnt = k & 0xFFFF
                latched = self._count(int(np.searchsorted(self.shutter_times_s, t, side="right")))
                out.append((t, 1, mk("AIR_DATA_TIME", {
                    "SampleCount": cnt, "SampleTime": round(k * 1e4 / self.cfg.sample_rate_hz) & 0xFFFFFFFF,
                    "ShutterCountLatched": latched}, False)))
                for name, sigs in (("AIR_DATA_1", ("IAS", "PressureAltitude")),
                                   ("ATTITUDE", ("Pitch", "Roll", "Heading")),
                                   ("DME", ("DME1Range", "DME2Range"))):
                    out.append((t, 2, mk(name, {"SampleCount": cnt,
                                                **{s: float(ad[s][j]) for s in sigs}})))
        out.sort(key=lambda m: (m[0], m[1]))
        return [m for _, _, m in out]

    def _count(self, n: int) -> int:
        return (self.cfg.shutter_count_start + n) & 0xFFFF

    def send(self, bus: Any, t0: float, t1: float) -> int:
        """Put the messages of [t0, t1) on ``bus``; returns how many."""
        msgs = self.messages(t0, t1)
        for m in msgs:
            bus.send(m)
        return len(msgs)
