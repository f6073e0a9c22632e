"""``radar-io calibrate …``: the calibration toolkit on the command line (JSON on stdout).

Heavy modules are imported inside the handlers so that ``radar-io`` starts fast.
See docs/calibration.md for the CSV columns of every step.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from radar_io.cli.argtypes import finite_float as _finite_float
from radar_io.cli.argtypes import positive_float as _positive_float
from radar_io.errors import CalibrationInputError
from radar_io.textfiles import json_safe


# ----------------------------------------------------------------- argument types
def _floats(n: int, what: str):
    def parse(text: str) -> list[float]:
        parts = [s.strip() for s in text.split(",")]
        try:
            values = [float(s) for s in parts]
        except ValueError:
            values = []
        if len(values) != n or not all(math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(f"expected {what} ({n} comma-separated numbers), got {text!r}")
        return values

    return parse


def _int_at_least(low: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            v = low - 1
        if v < low:
            raise argparse.ArgumentTypeError(f"expected an integer ≥ {low}, got {text!r}")
        return v

    return parse


# ----------------------------------------------------------------- output
def _emit(doc: dict[str, Any]) -> int:
    sys.stdout.write(json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n")
    return 0


# ----------------------------------------------------------------- handlers
def _cmd_resection(args: argparse.Namespace) -> int:
    import numpy as np

    from radar_io.calibration.montecarlo import monte_carlo
    from radar_io.calibration.refraction import correct_refraction
    from radar_io.calibration.resection import Pose, resect
    from radar_io.calibration.tables import read_table

    table = read_table(args.points, min_rows=1)
    table.require("x_m", "y_m", "z_m", "px_mm", "py_mm")
    points = np.column_stack([table.floats(c) for c in ("x_m", "y_m", "z_m")])
    film = np.column_stack([table.floats(c) for c in ("px_mm", "py_mm")])
    weights = None
    if table.has("wx") or table.has("wy"):
        table.require("wx", "wy")
        weights = np.column_stack([table.floats("wx"), table.floats("wy")])
    if args.refraction:
        if args.aircraft_height_m is None:
            raise CalibrationInputError(
                "--refraction needs --aircraft-height-m (aircraft height above sea level)")
        film = correct_refraction(film, args.focal_mm, args.aircraft_height_m,
                                  args.site_height_m - points[:, 2])
    start = Pose(*args.start) if args.start is not None else None
    result = resect(points, film, args.focal_mm, start=start, weights=weights,
                    max_iterations=args.max_iterations)
    doc: dict[str, Any] = {
        **result.pose.to_dict(),
        "iterations": result.iterations,
        "rms_mm": result.rms_mm,
        "n_points": len(points),
        "sigma": result.sigma,
        "residuals_mm": result.residuals_mm,
    }
    if args.refraction:
        doc["refraction"] = {"aircraft_height_m": args.aircraft_height_m, "site_height_m": args.site_height_m}
    if args.monte_carlo is not None:
        mc = monte_carlo(points, args.focal_mm, result, runs=args.monte_carlo, seed=args.seed,
                         weights=weights)
        doc["monte_carlo"] = mc.std
        doc["monte_carlo_info"] = {
            "runs": mc.runs,
            "seed": mc.seed,
            "sigma_px_mm": mc.sigma_mm[0],
            "sigma_py_mm": mc.sigma_mm[1],
        }
    return _emit(doc)


def _cmd_bias(args: argparse.Namespace) -> int:
    from radar_io.calibration.bias import bias_calibration, bias_statistics, photo_to_radar
    from radar_io.calibration.tables import read_table
    from radar_io.decoding.biases import save_calibration

    table = read_table(args.pairs, min_rows=1)
    table.require("group", "radar_sr_m", "radar_el_deg", "radar_az_deg")
    xyz = ("photo_x_m", "photo_y_m", "photo_z_m")
    sea = ("photo_sr_m", "photo_el_deg", "photo_az_deg")
    has_xyz, has_sea = any(table.has(c) for c in xyz), any(table.has(c) for c in sea)
    if has_xyz == has_sea:
        raise CalibrationInputError(
            f"{table.path}: give either photo_x_m,photo_y_m,photo_z_m or "
            "photo_sr_m,photo_el_deg,photo_az_deg"
            + (" (not both)" if has_xyz else "")
        )
    cols = xyz if has_xyz else sea
    table.require(*cols)
    photo = tuple(table.floats(c) for c in cols)
    if has_xyz:
        photo = photo_to_radar(*photo)
    radar = tuple(table.floats(c) for c in ("radar_sr_m", "radar_el_deg", "radar_az_deg"))
    groups = table.strings("group")
    for name, line in zip(groups, table.lines, strict=True):
        if not name:
            raise CalibrationInputError(f"{table.path}, line {line}, column group: empty group name")
    stats = bias_statistics(groups, photo, radar)
    if args.output is not None:
        cal = bias_calibration(
            stats,
            cal_id=args.id or f"bias-{table.path.stem}",
            provenance={
                "tool": "radar-io calibrate bias",
                "method": "calibration.md §8 (photo − radar; combined = mean of per-group means and stds)",
                "input": table.path.name,
                "input_sha256": table.sha256,
                "pairs": len(table),
                "groups": len(stats["groups"]),
                "photo_columns": list(cols),
            },
        )
        try:
            save_calibration(cal, args.output)
        except OSError as exc:
            raise CalibrationInputError(
                f"cannot write calibration set {args.output}: {exc.strerror or exc}") from exc
    return _emit(stats)


def _cmd_camera(args: argparse.Namespace) -> int:
    import numpy as np

    from radar_io.calibration.camera import calibrate_axis, scan_delta_theta
    from radar_io.calibration.tables import read_table

    table = read_table(args.targets, min_rows=4)
    table.require("axis", "theta_deg", "film_mm")
    theta, film = table.floats("theta_deg"), table.floats("film_mm")
    axes = [a.lower() for a in table.strings("axis")]
    for a, line in zip(axes, table.lines, strict=True):
        if a not in ("x", "y"):
            raise CalibrationInputError(f"{table.path}, line {line}, column axis: expected x or y, got {a!r}")
    names = [a for a in ("x", "y") if a in axes]
    sel = {a: np.array([b == a for b in axes]) for a in names}
    for a in names:
        if sel[a].sum() < 4:
            raise CalibrationInputError(
                f"{table.path}: axis {a} needs at least 4 targets (E_0 … E_3), got {sel[a].sum()}")
    f_nom = args.focal_mm
    if f_nom is None:
        f_nom = float(np.mean([
            np.mean(scan_delta_theta(theta[sel[a]], film[sel[a]], range_deg=args.scan_range_deg)[1])
            for a in names]))
    out: dict[str, Any] = {"focal_nominal_mm": f_nom, "axes": {}}
    for a in names:
        c = calibrate_axis(theta[sel[a]], film[sel[a]], focal_nominal_mm=f_nom, range_deg=args.scan_range_deg)
        out["axes"][a] = {
            "n": int(sel[a].sum()),
            "delta_theta_deg": c.delta_theta_deg,
            "focal_mm": c.focal_mm,
            "focal_std_mm": c.focal_std_mm,
            "focal_per_point_mm": c.focal_per_point_mm,
            "principal_point_mm": c.principal_point_mm,
            "distortion": dict(zip(("a0", "a1", "a2", "a3"), c.distortion.tolist(), strict=True)),
            "distortion_rms_mm": float(np.sqrt(np.mean(c.distortion_residuals_mm**2))),
            "ideal_mm": c.ideal_mm,
        }
    return _emit(out)


def _cmd_mapgrid(args: argparse.Namespace) -> int:
    import numpy as np

    from radar_io.calibration.mapgrid import fit_quadratic_model, japan_zone_crs, map_to_local
    from radar_io.calibration.tables import read_table
    from radar_io.errors import CalibrationError

    if (args.crs is None) == (args.zone is None):
        raise CalibrationInputError("give either --crs or --zone (with --datum)")
    crs = args.crs if args.crs is not None else japan_zone_crs(args.zone, args.datum)
    table = read_table(args.points, min_rows=1)
    table.require("map_x_m", "map_y_m", "map_h_m")
    pts = np.column_stack([table.floats(c) for c in ("map_x_m", "map_y_m", "map_h_m")])
    names = table.strings("name") if table.has("name") else [str(i + 1) for i in range(len(table))]
    conv = map_to_local(pts, np.array(args.site), crs, geoid_height_m=args.geoid_height_m)
    diff = conv.differences_m
    model, note = None, ""
    try:
        model = fit_quadratic_model(conv.map_relative_m[:, :2], diff)
    except CalibrationError as exc:
        note = str(exc)
    doc: dict[str, Any] = {
        "crs": crs,
        "crs_name": conv.crs_name,
        "site": dict(zip(("lat_deg", "lon_deg", "h_m"), conv.site_geodetic, strict=True)),
        "points": [],
    }
    for i, name in enumerate(names):
        p = {"name": name, "x_m": conv.ned_m[i, 0], "y_m": conv.ned_m[i, 1], "z_m": conv.ned_m[i, 2]}
        p.update(zip(("dx_m", "dy_m", "dh_m"), diff[i], strict=True))
        if model is not None:
            p["model_residual_m"] = model.residuals_m[i]
        doc["points"].append(p)
    if model is None:
        doc["model"] = None
        doc["model_note"] = note
    else:
        doc["model"] = {
            axis: {
                **{f"b{k + 1}": float(model.coefficients[j, k]) for k in range(5)},
                "rms_m": float(np.sqrt(np.mean(model.residuals_m[:, j] ** 2))),
                "max_abs_m": float(np.max(np.abs(model.residuals_m[:, j]))),
            }
            for j, axis in enumerate(("x", "y", "h"))
        }
    return _emit(doc)


# ----------------------------------------------------------------- parser
def add_subparser(subparsers: Any) -> None:
    """Add ``calibrate`` with the steps resection, bias, camera, mapgrid to ``radar-io``."""
    p = subparsers.add_parser(
        "calibrate",
        help="photogrammetric radar calibration (resection, bias, camera, mapgrid)",
        description="Photogrammetric radar calibration (calibration.md). JSON on stdout.",
    )
    steps = p.add_subparsers(dest="calibrate_step", metavar="STEP")

    def no_step(_args: argparse.Namespace) -> int:
        p.print_help(sys.stderr)
        return 2

    p.set_defaults(func=no_step)

    r = steps.add_parser(
        "resection",
        help="camera position/attitude from one photo's control points",
        description="Single-photo resection (calibration.md §1-§3). CSV columns x_m,y_m,z_m "
        "(ground frame: X north, Y east, Z down, origin at the radar), px_mm,py_mm (film, from the "
        "principal point); optional wx,wy weights. Angles in degrees. Negative option values: --start=-1,...",
    )
    r.add_argument("points", metavar="POINTS.csv")
    r.add_argument("--focal-mm", type=_positive_float, required=True, help="focal length F (mm)")
    r.add_argument("--start", type=_floats(6, "X0,Y0,Z0,PHI,THETA,PSI"), metavar="X0,Y0,Z0,PHI,THETA,PSI",
                   help="starting pose (m, deg); default: derived from the points")
    r.add_argument("--refraction", action="store_true", help="apply the refraction correction (§5) first")
    r.add_argument("--aircraft-height-m", type=_finite_float,
                   help="aircraft height above sea level (m), for --refraction")
    r.add_argument("--site-height-m", type=_finite_float, default=0.0,
                   help="radar height above sea level (m); ground heights are this minus z_m (default 0)")
    r.add_argument("--max-iterations", type=_int_at_least(1), default=20)
    r.add_argument("--monte-carlo", type=_int_at_least(2), metavar="M", help="Monte Carlo runs (§9)")
    r.add_argument("--seed", type=_int_at_least(0), help="Monte Carlo seed (default: fresh, reported)")
    r.set_defaults(func=_cmd_resection)

    b = steps.add_parser(
        "bias",
        help="radar SR/EL/AZ biases from photo positions",
        description="Radar bias (calibration.md §8). CSV columns group,radar_sr_m,radar_el_deg,"
        "radar_az_deg and either photo_x_m,photo_y_m,photo_z_m (Z down) or "
        "photo_sr_m,photo_el_deg,photo_az_deg.",
    )
    b.add_argument("pairs", metavar="PAIRS.csv")
    b.add_argument("-o", "--output", metavar="CAL.json",
                   help="also write the calibration set (biases = combined means)")
    b.add_argument("--id", help="calibration set id (default bias-<input stem>)")
    b.set_defaults(func=_cmd_bias)

    c = steps.add_parser(
        "camera",
        help="Δθ, focal length, principal point and distortion from targets",
        description="Camera calibration (calibration.md §4). CSV columns axis (x or y), theta_deg "
        "(angle to the target), film_mm (from the mechanical centre); the first row of each axis "
        "is E_0.",
    )
    c.add_argument("targets", metavar="TARGETS.csv")
    c.add_argument("--focal-mm", type=_positive_float,
                   help="nominal focal length F_nom (default: mean fitted F)")
    c.add_argument("--scan-range-deg", type=_positive_float, default=5.0,
                   help="Δθ scanned over ±this (default 5)")
    c.set_defaults(func=_cmd_camera)

    m = steps.add_parser(
        "mapgrid",
        help="Japanese plane rectangular map coordinates to the radar's local frame",
        description="Map grid → radar local frame (calibration.md §7). CSV columns map_x_m (northing), "
        "map_y_m (easting), map_h_m, optional name. Output x_m,y_m,z_m north/east/down from the radar.",
    )
    m.add_argument("points", metavar="POINTS.csv")
    m.add_argument("--site", type=_floats(3, "X,Y,H"), required=True, metavar="X,Y,H",
                   help="radar map coordinates: northing, easting, height (m)")
    m.add_argument("--crs", help="projected CRS, e.g. EPSG:30169 (Tokyo datum zone IX)")
    m.add_argument("--zone", type=_int_at_least(1),
                   help="Japan plane rectangular zone 1-19 (instead of --crs)")
    m.add_argument("--datum", choices=("tokyo", "jgd2000", "jgd2011"), default="jgd2011", help="with --zone")
    m.add_argument("--geoid-height-m", type=_finite_float, default=0.0,
                   help="geoid-ellipsoid separation added to all heights (m, default 0)")
    m.set_defaults(func=_cmd_mapgrid)
