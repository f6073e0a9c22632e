"""Japanese plane rectangular map coordinates → the radar's local frame (calibration.md §7, appendix C).

Map coordinates follow the Japanese convention: **x = northing, y = easting**
(metres, in the zone's projected CRS), h = height (m).  The chain is

1. zone (x, y) → geodetic latitude/longitude on the map's own datum
   (pyproj inverse projection: EPSG:30161…30179 Tokyo datum/Bessel 1841,
   EPSG:2443…2461 JGD2000, EPSG:6669…6687 JGD2011, zones I…XIX);
2. geodetic (lat, lon, h) → earth-centred coordinates on the same datum (pyproj, C-6 … C-8);
3. earth-centred → north/east/up at the radar with the rows of C-9, reported as
   north/east/**down** (x_m, y_m, z_m), the ground frame of the resection.

The local frame is that of the map's datum ellipsoid, as in the source; no
datum transformation is made.  Heights are used as ellipsoidal heights on that
datum: pass ``geoid_height_m`` (a constant geoid–ellipsoid separation) to
convert orthometric map heights (it mostly cancels in the local frame, but a
40 m offset changes horizontal distances by ≈ 6 ppm).

The quadratic error model (C-13 … C-15) fits local − map-relative coordinates
per axis as ``b1 + b2 X' + b3 X'² + b4 Y' + b5 Y'²``.  The source's Gauss–Krüger
series (C-1, C-2) is :func:`gauss_kruger_series`, kept only as a cross-check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from radar_io.errors import CalibrationError

#: EPSG code of zone I per datum; zone k is base + k (k = 1 … 19)
_ZONE_BASE = {"tokyo": 30160, "jgd2000": 2442, "jgd2011": 6668}


def japan_zone_crs(zone: int, datum: str = "jgd2011") -> str:
    """``"EPSG:nnnn"`` of Japan plane rectangular zone 1…19 on datum ``tokyo``, ``jgd2000`` or ``jgd2011``."""
    key = datum.strip().lower()
    if key not in _ZONE_BASE:
        raise CalibrationError(f"unknown datum {datum!r}; use one of {sorted(_ZONE_BASE)}")
    if not (isinstance(zone, int) and 1 <= zone <= 19):
        raise CalibrationError(f"Japan plane rectangular zone must be 1 … 19, got {zone!r}")
    return f"EPSG:{_ZONE_BASE[key] + zone}"


@lru_cache(maxsize=16)
def _transformers(crs_text: str):
    import pyproj
    from pyproj.crs import GeocentricCRS

    try:
        crs = pyproj.CRS.from_user_input(crs_text)
    except pyproj.exceptions.CRSError as exc:
        raise CalibrationError(f"unknown coordinate reference system {crs_text!r}: {exc}") from exc
    if not crs.is_projected:
        raise CalibrationError(f"{crs_text!r} ({crs.name}) is not a projected (map grid) CRS")
    geog = crs.geodetic_crs
    if geog is None or geog.datum is None:
        raise CalibrationError(f"{crs_text!r} ({crs.name}) names no geodetic datum")
    to_geog = pyproj.Transformer.from_crs(crs, geog, always_xy=True)
    geocentric = GeocentricCRS(name=f"{geog.datum.name} geocentric", datum=geog.datum)
    to_ecef = pyproj.Transformer.from_crs(geog.to_3d(), geocentric, always_xy=True)
    return crs, to_geog, to_ecef


@dataclass(frozen=True)
class LocalConversion:
    """Map points in the radar's local frame.

    ``ned_m`` (N, 3): north, east, down from the radar (m).  ``map_relative_m``
    (N, 3): X'_m, Y'_m, H'_m = map coordinates minus the radar's (C-5).
    ``site_geodetic``: radar latitude, longitude (deg, map datum) and height (m).
    """

    crs_name: str
    ned_m: np.ndarray
    map_relative_m: np.ndarray
    geodetic: np.ndarray
    site_geodetic: tuple[float, float, float]

    @property
    def differences_m(self) -> np.ndarray:
        """Local − map-relative per axis (north, east, up) (N, 3), the Δ of C-13 … C-15."""
        local_neu = self.ned_m * np.array([1.0, 1.0, -1.0])
        return local_neu - self.map_relative_m


def _geodetic(to_geog, xy_h: np.ndarray, geoid_height_m: float) -> np.ndarray:
    lon, lat = to_geog.transform(xy_h[:, 1], xy_h[:, 0])  # always_xy: (easting, northing) → (lon, lat)
    lat, lon = np.atleast_1d(lat), np.atleast_1d(lon)
    if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon))):
        raise CalibrationError("map coordinates outside the projection's domain")
    return np.column_stack([lat, lon, xy_h[:, 2] + geoid_height_m])


def ned_rotation(lat_deg: float, lon_deg: float) -> np.ndarray:
    """Rows north, east, down of the local frame at (lat, lon) in earth-centred axes (C-9, up negated)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl, sm, cm = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array(
        [
            [-sl * cm, -sl * sm, cl],
            [-sm, cm, 0.0],
            [-cl * cm, -cl * sm, -sl],
        ]
    )


def map_to_local(
    points_map: np.ndarray, site_map: np.ndarray, crs: str, *, geoid_height_m: float = 0.0
) -> LocalConversion:
    """Map points (N, 3) [x north, y east, h] and the radar site (3,) in zone CRS ``crs`` → local NED."""
    pts = np.asarray(points_map, dtype=float)
    site = np.asarray(site_map, dtype=float).reshape(-1)
    if pts.ndim != 2 or pts.shape[1] != 3 or site.shape != (3,):
        raise CalibrationError("map points must be (N, 3) and the site (3,): x north, y east, h")
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(site)) and math.isfinite(geoid_height_m)):
        raise CalibrationError("map coordinates must be finite")
    crs_obj, to_geog, to_ecef = _transformers(str(crs))
    geo = _geodetic(to_geog, pts, geoid_height_m)
    site_geo = _geodetic(to_geog, site[None, :], geoid_height_m)[0]
    ecef = np.column_stack(to_ecef.transform(geo[:, 1], geo[:, 0], geo[:, 2]))
    site_ecef = np.array(to_ecef.transform(site_geo[1], site_geo[0], site_geo[2]), dtype=float)
    ned = (ecef - site_ecef) @ ned_rotation(site_geo[0], site_geo[1]).T
    return LocalConversion(
        crs_name=crs_obj.name,
        ned_m=ned,
        map_relative_m=pts - site,
        geodetic=geo,
        site_geodetic=(float(site_geo[0]), float(site_geo[1]), float(site_geo[2])),
    )


# ----------------------------------------------------------------- quadratic model (C-13 … C-15)
@dataclass(frozen=True)
class QuadraticModel:
    """Δ = b1 + b2 X' + b3 X'² + b4 Y' + b5 Y'² per axis; ``coefficients`` (3 axes, 5), SI units."""

    coefficients: np.ndarray
    residuals_m: np.ndarray

    def predict(self, map_relative_xy_m: np.ndarray) -> np.ndarray:
        """Δ (N, 3) north, east, up at map-relative (X', Y') (N, 2)."""
        return _design(np.asarray(map_relative_xy_m, dtype=float)) @ self.coefficients.T


def _design(xy: np.ndarray) -> np.ndarray:
    x, y = xy[:, 0], xy[:, 1]
    return np.column_stack([np.ones_like(x), x, x**2, y, y**2])


def fit_quadratic_model(map_relative_xy_m: np.ndarray, differences_m: np.ndarray) -> QuadraticModel:
    """Least-squares fit of the C-13 … C-15 quadratic to Δ (N, 3) over map-relative (X', Y') (N, 2)."""
    xy = np.asarray(map_relative_xy_m, dtype=float)
    d = np.asarray(differences_m, dtype=float)
    a = _design(xy)
    scale = np.max(np.abs(a), axis=0)
    scale[scale == 0] = 1.0
    if len(xy) < 5 or np.linalg.matrix_rank(a / scale) < 5:
        raise CalibrationError(
            "the quadratic map model needs at least 5 points spread in both map directions"
        )
    b = np.linalg.lstsq(a / scale, d, rcond=None)[0] / scale[:, None]
    return QuadraticModel(coefficients=b.T, residuals_m=d - a @ b)


# ----------------------------------------------------------------- Gauss–Krüger series (cross-check only)
def gauss_kruger_series(
    lat_deg: np.ndarray,
    lon_deg: np.ndarray,
    lat0_deg: float,
    lon0_deg: float,
    a: float,
    f: float,
    k0: float = 0.9999,
) -> tuple[np.ndarray, np.ndarray]:
    """Classical Gauss–Krüger series (C-1, C-2): geodetic → (x north, y east) m.

    Meridian arc by Helmert's series in n = f/(2 − f); terms to Δλ⁸.  For
    cross-checking pyproj only; use :func:`map_to_local` for real work.
    """
    phi = np.radians(np.asarray(lat_deg, dtype=float))
    dl = np.radians(np.asarray(lon_deg, dtype=float) - lon0_deg)
    e2 = f * (2.0 - f)
    ep2 = e2 / (1.0 - e2)
    n = f / (2.0 - f)

    def arc(p):
        return (
            a
            / (1.0 + n)
            * (
                (1.0 + n**2 / 4.0 + n**4 / 64.0) * p
                - 1.5 * (n - n**3 / 8.0) * np.sin(2.0 * p)
                + 15.0 / 16.0 * (n**2 - n**4 / 4.0) * np.sin(4.0 * p)
                - 35.0 / 48.0 * n**3 * np.sin(6.0 * p)
                + 315.0 / 512.0 * n**4 * np.sin(8.0 * p)
            )
        )

    c, t = np.cos(phi), np.tan(phi)
    t2 = t * t
    eta2 = ep2 * c * c
    big_n = a / np.sqrt(1.0 - e2 * np.sin(phi) ** 2)
    x = (
        arc(phi)
        - arc(math.radians(lat0_deg))
        + big_n * t * c**2 * dl**2 / 2.0
        + big_n * t * c**4 * dl**4 * (5.0 - t2 + 9.0 * eta2 + 4.0 * eta2**2) / 24.0
        + big_n * t * c**6 * dl**6 * (61.0 - 58.0 * t2 + t2**2 + 270.0 * eta2 - 330.0 * t2 * eta2) / 720.0
        + big_n * t * c**8 * dl**8 * (1385.0 - 3111.0 * t2 + 543.0 * t2**2 - t2**3) / 40320.0
    )
    y = (
        big_n * c * dl
        + big_n * c**3 * dl**3 * (1.0 - t2 + eta2) / 6.0
        + big_n * c**5 * dl**5 * (5.0 - 18.0 * t2 + t2**2 + 14.0 * eta2 - 58.0 * t2 * eta2) / 120.0
        + big_n * c**7 * dl**7 * (61.0 - 479.0 * t2 + 179.0 * t2**2 - t2**3) / 5040.0
    )
    return k0 * x, k0 * y
