"""Reference path and path deviation (radar-interface.md §6).

A path file lists 3-D pass points joined by straight legs; each interior
corner is filleted in the horizontal plane by a circular arc of the path's
turn radius. The horizontal path is therefore a chain of *elements*::

    element 0        straight, pass point 0 -> first tangent point (leg 0)
    element 2i-1     arc filleting the corner at pass point i   (i = 1 .. n-2)
    element 2i       straight part of leg i (pass point i -> i+1)

so an even ``leg`` value ``2j`` is the straight part of leg j and an odd value
``2i-1`` is the turn at pass point i. Before pass point 0 and after the last
pass point the first and last straight legs are extended indefinitely
(``along_m`` < 0, resp. > :attr:`ReferencePath.length_m`, and ``leg`` is the
first resp. last element).

Heights vary linearly with along-track distance between *stations*: pass
point 0 at along 0, the last pass point at the path length, and each interior
pass point at the midpoint of its fillet arc (the path's closest point to the
corner); before the first and after the last station the first and last
slopes are extended. The path is thus a 3-D straight line along an extended
first or last leg.

Deviation of an aircraft position is taken at the horizontally closest point
of the path (exact circle geometry on arcs): ``dy_m`` is positive right of the
path looking along the direction of flight, ``dz_m = H - H_path(along)`` is
positive above. Both frames radar_io uses have Y 90 degrees clockwise of X seen
from above (radar: X north, Y east; runway: X_r along the approach, Y_r right),
so one formula serves both: the right-hand normal of the unit direction
(u_x, u_y) is (-u_y, u_x), and a corner with u_in x u_out > 0 is a right turn.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from radar_io.decoding.measurement import MeasurementBatch
from radar_io.errors import ConfigError
from radar_io.textfiles import Fields, read_toml

#: columns added by :func:`add_deviation`
DEVIATION_COLUMNS = ("dy_m", "dz_m", "along_m", "leg")
#: position columns read for each path frame
FRAME_COLUMNS = {"radar": ("x_m", "y_m", "h_m"), "runway": ("xr_m", "yr_m", "hr_m")}
_TOP_KEYS = {"frame", "turn_radius_m", "points", "name", "description"}
_POINT_KEYS = {"x_m", "y_m", "h_m", "name"}


class PathError(ConfigError):
    """A reference path file is missing, malformed or geometrically impossible."""


@dataclass(frozen=True)
class _Element:
    kind: str            # "line" or "arc"
    s0: float            # along-track distance at the element's start
    length: float
    ax: float            # start point
    ay: float
    ux: float = 0.0      # line: unit direction
    uy: float = 0.0
    cx: float = 0.0      # arc: centre, unit vector centre -> start, turn sign (+1 right)
    cy: float = 0.0
    a0x: float = 0.0
    a0y: float = 0.0
    turn: float = 0.0
    sweep: float = 0.0   # arc: turn angle (rad, > 0)
    open_start: bool = False  # line extended backwards (first leg)
    open_end: bool = False    # line extended forwards (last leg)


class ReferencePath:
    """A filleted 3-D reference path; see the module docstring for the conventions."""

    def __init__(self, points: np.ndarray, turn_radius_m: float, frame: str = "radar",
                 name: str = "", source: str = "<memory>") -> None:
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise PathError(f"{source}: points must be an (n, 3) array of x, y, h")
        if frame not in FRAME_COLUMNS:
            raise PathError(f"{source}: frame must be 'radar' or 'runway', got {frame!r}")
        if len(pts) < 2:
            raise PathError(f"{source}: a path needs at least 2 pass points, got {len(pts)}")
        if not np.all(np.isfinite(pts)):
            raise PathError(f"{source}: pass point coordinates must be finite numbers")
        r = float(turn_radius_m)
        if not (math.isfinite(r) and r > 0):
            raise PathError(f"{source}: turn_radius_m must be a positive number, got {turn_radius_m!r}")
        self.points, self.turn_radius_m, self.frame, self.name = pts, r, frame, name
        self.columns = FRAME_COLUMNS[frame]
        self._build(source)

    # ------------------------------------------------------------ construction
    def _build(self, source: str) -> None:
        p, r = self.points, self.turn_radius_m
        n = len(p)
        d = np.diff(p[:, :2], axis=0)
        legs = np.hypot(d[:, 0], d[:, 1])
        for j, length in enumerate(legs):
            if length == 0.0:
                raise PathError(f"{source}: pass points {j} and {j + 1} have the same horizontal "
                                f"position ({p[j, 0]}, {p[j, 1]})")
        u = d / legs[:, None]
        tangent = np.zeros(n)          # fillet tangent length at each pass point
        theta = np.zeros(n)            # signed turn angle, + = right
        for i in range(1, n - 1):
            cross = u[i - 1, 0] * u[i, 1] - u[i - 1, 1] * u[i, 0]
            dot = u[i - 1, 0] * u[i, 0] + u[i - 1, 1] * u[i, 1]
            theta[i] = math.atan2(cross, dot)
            if abs(theta[i]) > math.pi - 1e-9:
                raise PathError(f"{source}: the path reverses direction at pass point {i}")
            tangent[i] = r * math.tan(abs(theta[i]) / 2.0)
        for j, length in enumerate(legs):
            need = tangent[j] + tangent[j + 1]
            if need > length * (1.0 + 1e-12):
                raise PathError(
                    f"{source}: turn_radius_m = {r:g} is too large for the corner(s) of leg {j} "
                    f"(pass points {j} -> {j + 1}): the fillets need {need:.1f} m of its "
                    f"{length:.1f} m")
        elements: list[_Element] = []
        stations = [0.0]
        s = 0.0
        for j in range(n - 1):
            ax, ay = p[j, :2] + tangent[j] * u[j]
            length = max(legs[j] - tangent[j] - tangent[j + 1], 0.0)
            elements.append(_Element("line", s, length, ax, ay, ux=u[j, 0], uy=u[j, 1],
                                     open_start=j == 0, open_end=j == n - 2))
            s += length
            i = j + 1
            if i == n - 1:
                break
            sweep = abs(theta[i])
            turn = 1.0 if theta[i] > 0 else -1.0
            bx, by = p[i, :2] - tangent[i] * u[j]      # arc start (tangent point on leg j)
            # centre: on the right-hand normal (-u_y, u_x) for a right turn, the left for a left turn
            cx, cy = bx - turn * r * u[j, 1], by + turn * r * u[j, 0]
            elements.append(_Element("arc", s, r * sweep, bx, by, cx=cx, cy=cy,
                                     a0x=(bx - cx) / r, a0y=(by - cy) / r, turn=turn, sweep=sweep))
            stations.append(s + r * sweep / 2.0)
            s += r * sweep
        stations.append(s)
        self.elements: tuple[_Element, ...] = tuple(elements)
        self.stations_m = np.array(stations)
        self.length_m = s
        st, h = self.stations_m, p[:, 2]
        self._slope_first = (h[1] - h[0]) / (st[1] - st[0])
        self._slope_last = (h[-1] - h[-2]) / (st[-1] - st[-2])

    # ------------------------------------------------------------ queries
    def height(self, along_m: Any) -> np.ndarray:
        """Path height at along-track distance(s), linear between stations, extended at both ends."""
        s = np.asarray(along_m, dtype=np.float64)
        st, h = self.stations_m, self.points[:, 2]
        out = np.interp(s, st, h)
        out = np.where(s < st[0], h[0] + (s - st[0]) * self._slope_first, out)
        return np.where(s > st[-1], h[-1] + (s - st[-1]) * self._slope_last, out)

    def slope(self, along_m: Any) -> np.ndarray:
        """dH/d(along) of the path at along-track distance(s) (the height's slope between
        the stations around each point; the first / last slope beyond the ends)."""
        s = np.asarray(along_m, dtype=np.float64)
        st, h = self.stations_m, self.points[:, 2]
        slopes = np.diff(h) / np.diff(st)
        k = np.clip(np.searchsorted(st, s, side="right") - 1, 0, slopes.size - 1)
        return np.where(np.isfinite(s), slopes[k], np.nan)

    def position(self, along_m: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Path point (x, y, h) at along-track distance(s) (for plots and examples)."""
        s = np.atleast_1d(np.asarray(along_m, dtype=np.float64))
        x, y = np.full(s.shape, np.nan), np.full(s.shape, np.nan)
        ends = np.array([e.s0 for e in self.elements[1:]])
        k = np.searchsorted(ends, s, side="right")
        for i, e in enumerate(self.elements):
            m = k == i
            if not m.any():
                continue
            ds = s[m] - e.s0
            if e.kind == "line":
                x[m], y[m] = e.ax + ds * e.ux, e.ay + ds * e.uy
            else:
                phi = e.turn * ds / self.turn_radius_m
                c, sn = np.cos(phi), np.sin(phi)
                r = self.turn_radius_m
                x[m] = e.cx + r * (e.a0x * c - e.a0y * sn)
                y[m] = e.cy + r * (e.a0x * sn + e.a0y * c)
        return x, y, self.height(s)

    def deviation(self, x_m: Any, y_m: Any, h_m: Any) -> dict[str, np.ndarray]:
        """``dy_m``, ``dz_m``, ``along_m``, ``leg`` of positions: NaN / -1 where X or Y is NaN;
        a NaN height alone leaves the horizontal answer and makes only ``dz_m`` NaN."""
        x, y, h = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x_m, y_m, h_m)))
        shape = x.shape
        x, y, h = x.ravel(), y.ravel(), h.ravel()
        best = np.full(x.shape, np.inf)
        dy = np.full(x.shape, np.nan)
        along = np.full(x.shape, np.nan)
        leg = np.full(x.shape, -1, dtype=np.int64)
        r = self.turn_radius_m
        with np.errstate(invalid="ignore"):
            for k, e in enumerate(self.elements):
                if e.kind == "line":
                    rx, ry = x - e.ax, y - e.ay
                    t = rx * e.ux + ry * e.uy
                    tc = np.clip(t, -np.inf if e.open_start else 0.0,
                                 np.inf if e.open_end else e.length)
                    side = ry * e.ux - rx * e.uy               # (r . right-normal): + = right
                    dist = np.hypot(t - tc, side)
                    s_el = e.s0 + tc
                else:
                    if e.length == 0.0:
                        continue
                    vx, vy = x - e.cx, y - e.cy
                    d = np.hypot(vx, vy)
                    phi = e.turn * np.arctan2(e.a0x * vy - e.a0y * vx, e.a0x * vx + e.a0y * vy)
                    inside = (phi >= 0.0) & (phi <= e.sweep)
                    side = e.turn * (r - d)                    # centre lies on the turn side
                    dist = np.where(inside, np.abs(d - r), np.inf)
                    s_el = e.s0 + r * phi
                better = dist < best
                best = np.where(better, dist, best)
                dy = np.where(better, side, dy)
                along = np.where(better, s_el, along)
                leg[better] = k
        dz = h - self.height(along)
        return {"dy_m": dy.reshape(shape), "dz_m": dz.reshape(shape),
                "along_m": along.reshape(shape), "leg": leg.reshape(shape)}


def load_path(path: str | os.PathLike[str]) -> ReferencePath:
    """Read a path TOML file (see ``firmware_specs/paths/``); every field is checked and a bad
    one raises PathError naming the file and the field (``points[2].x_m``)."""
    p = Path(path)
    f = Fields(read_toml(p, "path file", PathError, allow_empty=False), p, "path file", PathError)
    f.only(*sorted(_TOP_KEYS))
    frame = f.string("frame", choices=tuple(FRAME_COLUMNS))
    radius = f.number("turn_radius_m", 0.0, 1e6, above=0.0)
    name = f.string("name", default=p.stem)
    f.string("description", default="")
    rows = []
    for q in f.tables("points", min_count=2):
        q.only(*sorted(_POINT_KEYS))
        q.string("name", default="")
        rows.append([q.number("x_m", -1e7, 1e7), q.number("y_m", -1e7, 1e7),
                     q.number("h_m", -1e4, 1e5)])
    return ReferencePath(np.array(rows, dtype=np.float64).reshape(-1, 3), radius, frame,
                         name=name, source=f"path file {p}")


def add_deviation(batch: MeasurementBatch, path: ReferencePath) -> MeasurementBatch:
    """A new batch with :data:`DEVIATION_COLUMNS` appended (NaN / leg -1 for NG samples).

    A radar-frame path reads ``x_m, y_m, h_m``; a runway-frame path reads
    ``xr_m, yr_m, hr_m``, which exist only when the batch was decoded with a site.
    """
    missing = [c for c in path.columns if c not in batch]
    if missing:
        hint = " (decode with --site)" if path.frame == "runway" else ""
        raise PathError(f"a {path.frame}-frame path needs column(s) {', '.join(missing)}{hint}")
    dev = path.deviation(*(batch[c] for c in path.columns))
    cols = {c: batch[c] for c in batch.columns}
    order = [c for c in batch.columns if c not in DEVIATION_COLUMNS] + list(DEVIATION_COLUMNS)
    cols.update(dev)
    return MeasurementBatch(cols, batch.stats, order)
