"""Coordinates of radar-interface.md §5: radar rectangular, runway, geodetic.

Pure functions, vectorised over numpy arrays (scalars work too). Angles in
degrees, distances in metres. Radar rectangular frame: origin at the antenna,
X north, Y east, H up (left-handed; Z = -H is the right-handed down axis).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from radar_io.errors import ConfigError
from radar_io.textfiles import Fields, read_toml

ArrayLike = Any


def radar_xyh(sr_m: ArrayLike, el_deg: ArrayLike, az_deg: ArrayLike) -> tuple[Any, Any, Any]:
    """Radar rectangular X (north), Y (east), H (up) from SR/EL/AZ, eqs. (2-3)…(2-5)."""
    el = np.deg2rad(el_deg)
    az = np.deg2rad(az_deg)
    r = sr_m * np.cos(el)
    return r * np.cos(az), r * np.sin(az), sr_m * np.sin(el)


def radar_sea(x_m: ArrayLike, y_m: ArrayLike, h_m: ArrayLike) -> tuple[Any, Any, Any]:
    """Inverse of :func:`radar_xyh`: SR, EL (deg), AZ (deg, folded to [0, 360))."""
    ground = np.hypot(x_m, y_m)
    sr = np.sqrt(np.square(x_m) + np.square(y_m) + np.square(h_m))
    el = np.rad2deg(np.arctan2(h_m, ground))
    az = np.mod(np.rad2deg(np.arctan2(y_m, x_m)), 360.0)
    az = np.where(az >= 360.0, az - 360.0, az)  # np.mod(-1e-14, 360) rounds to 360.0
    return sr, el, az


@dataclass(frozen=True)
class Site:
    """A radar site: WGS-84 antenna position and the runway frame around it."""

    name: str = "unspecified"
    lat_deg: float = 0.0
    lon_deg: float = 0.0
    h_m: float = 0.0
    runway_heading_deg: float = 0.0
    radar_xr_m: float = 0.0
    radar_yr_m: float = 0.0
    radar_hr_m: float = 0.0
    description: str = ""
    asterix_sac: int | None = None   #: ASTERIX System Area Code 0..255 ([asterix] sac), None if unset
    asterix_sic: int | None = None   #: ASTERIX System Identification Code 0..255 ([asterix] sic)
    sigma_range_m: float | None = None    #: range noise 1σ (m) for the tracker, None: the spec's
    sigma_angle_deg: float | None = None  #: angle noise 1σ (deg) for the tracker, None: the spec's

    def to_dict(self) -> dict[str, Any]:
        doc: dict[str, Any] = {
            "name": self.name, "description": self.description,
            "radar": {"lat_deg": self.lat_deg, "lon_deg": self.lon_deg, "h_m": self.h_m},
            "runway": {"heading_deg": self.runway_heading_deg, "radar_xr_m": self.radar_xr_m,
                       "radar_yr_m": self.radar_yr_m, "radar_hr_m": self.radar_hr_m},
        }
        for key in ("sigma_range_m", "sigma_angle_deg"):
            if getattr(self, key) is not None:
                doc["radar"][key] = getattr(self, key)
        if self.asterix_sac is not None:
            doc["asterix"] = {"sac": self.asterix_sac, "sic": self.asterix_sic}
        return doc


def site_names() -> list[str]:
    """Names of the packaged sites (``firmware_specs/sites/NAME.toml``)."""
    from radar_io.wirespec.frame import spec_dir

    return sorted(q.stem for q in (spec_dir() / "sites").glob("*.toml"))


def resolve_site(site: str | os.PathLike[str]) -> Path:
    """The file of ``site``: an existing path, else the packaged site of that name (``demo``)."""
    from radar_io.wirespec.frame import spec_dir

    p = Path(site)
    if p.exists() or os.sep in str(site) or p.suffix:
        return p
    named = spec_dir() / "sites" / f"{site}.toml"
    if named.is_file():
        return named
    raise ConfigError(f"site {str(site)!r}: no such file and no packaged site of that name "
                      f"(packaged: {', '.join(site_names()) or 'none'})")


#: [section] → keys allowed in a site file (docs/input-validation.md)
SITE_KEYS = {"radar": ("lat_deg", "lon_deg", "h_m", "sigma_range_m", "sigma_angle_deg"),
             "runway": ("heading_deg", "radar_xr_m", "radar_yr_m", "radar_hr_m"),
             "asterix": ("sac", "sic")}


def load_site(path: str | os.PathLike[str]) -> Site:
    """Read a site TOML file, or the packaged site named ``path`` (``"demo"``); every field
    is checked and a bad one raises ConfigError naming the file and the field."""
    p = resolve_site(path)
    f = Fields(read_toml(p, "site file", allow_empty=False), p, "site file")
    f.only("name", "description", *SITE_KEYS)
    radar = f.table("radar")
    runway = f.table("runway")
    asterix = f.table("asterix", required=False)
    assert radar is not None and runway is not None
    radar.only(*SITE_KEYS["radar"])
    runway.only(*SITE_KEYS["runway"])
    sac = sic = None
    if asterix is not None:
        asterix.only(*SITE_KEYS["asterix"])
        sac = asterix.integer("sac", 0, 255)
        sic = asterix.integer("sic", 0, 255)
    return Site(
        name=f.string("name", default=p.stem, nonempty=True),
        description=f.string("description", default=""),
        lat_deg=radar.number("lat_deg", -90, 90),
        lon_deg=radar.number("lon_deg", -180, 180),
        h_m=radar.number("h_m", -1000, 10000),
        runway_heading_deg=runway.number("heading_deg", -360, 360),
        radar_xr_m=runway.number("radar_xr_m", -1e6, 1e6),
        radar_yr_m=runway.number("radar_yr_m", -1e6, 1e6),
        radar_hr_m=runway.number("radar_hr_m", -1e4, 1e4),
        asterix_sac=sac,
        asterix_sic=sic,
        sigma_range_m=radar.number("sigma_range_m", above=0.0, hi=1000.0, default=None),
        sigma_angle_deg=radar.number("sigma_angle_deg", above=0.0, hi=10.0, default=None),
    )


def runway_xyh(sr_m: ArrayLike, el_deg: ArrayLike, az_deg: ArrayLike, site: Site
               ) -> tuple[Any, Any, Any]:
    """Runway frame X_r (along the approach heading), Y_r (right), H_r (up), eqs. (2-9)…(2-11)."""
    el = np.deg2rad(el_deg)
    rel = np.deg2rad(np.asarray(az_deg) - site.runway_heading_deg)
    r = sr_m * np.cos(el)
    return (r * np.cos(rel) + site.radar_xr_m,
            r * np.sin(rel) + site.radar_yr_m,
            sr_m * np.sin(el) + site.radar_hr_m)


def runway_to_radar(xr_m: ArrayLike, yr_m: ArrayLike, hr_m: ArrayLike, site: Site
                    ) -> tuple[Any, Any, Any]:
    """Radar rectangular X, Y, H of runway-frame points: the inverse of :func:`runway_xyh`."""
    p = np.deg2rad(site.runway_heading_deg)
    a = np.asarray(xr_m) - site.radar_xr_m
    b = np.asarray(yr_m) - site.radar_yr_m
    return a * np.cos(p) - b * np.sin(p), a * np.sin(p) + b * np.cos(p), \
        np.asarray(hr_m) - site.radar_hr_m


def geodetic(sr_m: ArrayLike, el_deg: ArrayLike, az_deg: ArrayLike, site: Site
             ) -> tuple[Any, Any, Any]:
    """WGS-84 latitude (deg), longitude (deg), ellipsoidal height (m) of a radar measurement.

    (AZ, EL, SR) are azimuth/elevation/slant range in the local north/east/up
    frame at the antenna, converted with pymap3d's AER→geodetic.
    """
    return pymap3d.aer2geodetic(az_deg, el_deg, sr_m, site.lat_deg, site.lon_deg, site.h_m,
                                deg=True)
