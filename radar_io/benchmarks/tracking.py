"""Tracking benchmark: ``radar-io track`` of a long 1 kHz recording → smoothed Parquet;
and the live filter's cost per chunk (``--live``).

``python -m radar_io.benchmarks.tracking [--hours 1]`` or ``radar-io bench --tracking-hours 1``;
``python -m radar_io.benchmarks.tracking --live`` or ``radar-io bench --tracking-live``

1. Simulates ``--hours`` at 1 kHz (``radar-io simulate``; the approach repeats, so the
   track restarts at each jump back).
2. Runs ``radar-io track REC -o out.parquet`` in fresh child processes timed from outside
   (interpreter start, imports, decoding, filter, smoother and the Parquet file all
   included): first with an empty numba cache (compilation included: the first run on a
   machine), then with the cache it left (every later run). Wall, CPU (user + sys) and
   peak RSS (the child's ``ru_maxrss``).
3. The anchor, in the same run: Stone Soup's ``ExtendedKalmanPredictor`` /
   ``ExtendedKalmanUpdater`` / ``ExtendedKalmanSmoother`` on 2 000 measurements of the same
   recording, in a child process; the ratio is Stone Soup's time per measurement over the
   CLI's end-to-end time per row. Skipped (and said so) when stonesoup is not installed
   (it is a test dependency only).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ANCHOR_MEASUREMENTS = 2000


def stonesoup_anchor(rec: str, n: int = ANCHOR_MEASUREMENTS) -> dict[str, float]:
    """Stone Soup EKF + RTS smoother on ``n`` good measurements (every 10th frame) of ``rec``:
    seconds per measurement (filter and smoother, imports and decoding excluded)."""
    import datetime as dt
    import math

    import numpy as np
    from stonesoup.models.measurement.nonlinear import CartesianToElevationBearingRange
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.smoother.kalman import ExtendedKalmanSmoother
    from stonesoup.types.angle import Bearing, Elevation
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    from radar_io.decoding.batch_decoder import decode_bytes
    from radar_io.recording.rdrlog import iter_payloads
    from radar_io.tracking.tracker import TrackParams

    data = b""
    for chunk in iter_payloads(rec):
        data += chunk
        if len(data) > 40 * n * 24:
            break
    b = decode_bytes(data)
    idx = np.flatnonzero(b["rx_good"] == 1)[::10][:n]
    p = TrackParams()
    sa = math.radians(p.sigma_angle_deg)
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(p.q_mps2)] * 3)
    model = CartesianToElevationBearingRange(
        ndim_state=6, mapping=(0, 2, 4),
        noise_covar=CovarianceMatrix(np.diag([sa ** 2, sa ** 2, p.sigma_range_m ** 2])))
    predictor, updater = ExtendedKalmanPredictor(transition), ExtendedKalmanUpdater(model)
    t0 = dt.datetime(2026, 1, 1)
    tod = b["tod_s"][idx]
    x0 = np.array([b["x_m"][idx[0]], 0.0, -b["y_m"][idx[0]], 0.0, b["h_m"][idx[0]], 0.0])
    start = time.perf_counter()
    track = Track([GaussianState(StateVector(x0), CovarianceMatrix(np.diag([25.0, 9e4] * 3)),
                                 timestamp=t0)])
    for k, i in enumerate(idx[1:], 1):
        when = t0 + dt.timedelta(seconds=float(tod[k] - tod[0]))
        z = StateVector([Elevation(math.radians(b["el_c_deg"][i])),
                         Bearing(-math.radians(b["az_c_deg"][i])), b["sr_c_m"][i]])
        pred = predictor.predict(track[-1], timestamp=when)
        track.append(updater.update(SingleHypothesis(
            pred, Detection(z, timestamp=when, measurement_model=model))))
    ExtendedKalmanSmoother(transition).smooth(track)
    elapsed = time.perf_counter() - start
    return {"measurements": float(len(idx)), "seconds": elapsed,
            "s_per_measurement": elapsed / len(idx)}


def run(hours: float = 1.0, workdir: str | None = None, keep: bool = False) -> dict[str, Any]:
    from radar_io.benchmarks.outputs import _run_child, make_recording

    tmp = Path(workdir or tempfile.mkdtemp(prefix="radar-io-bench-tracking-"))
    tmp.mkdir(parents=True, exist_ok=True)
    res: dict[str, Any] = {"hours": hours}
    cache = Path(tempfile.mkdtemp(prefix="radar-io-numba-cache-"))
    env_before = os.environ.get("NUMBA_CACHE_DIR")
    try:
        rec = tmp / "hour.rdrlog"
        if not rec.exists():
            res["simulate_s"] = make_recording(rec, hours)
        res["recording_mb"] = rec.stat().st_size / 1e6
        out = tmp / "bet.parquet"
        os.environ["NUMBA_CACHE_DIR"] = str(cache)   # the children inherit it
        for name in ("cold", "warm"):
            res[f"{name}_s"], res[f"{name}_cpu_s"], res[f"{name}_rss_mb"] = _run_child(
                ["-m", "radar_io.cli", "track", str(rec), "-o", str(out), "-q"])
        import pyarrow.parquet as pq

        meta = pq.read_metadata(out)
        res["rows"] = meta.num_rows
        kv = {k.decode(): v.decode() for k, v in (meta.metadata or {}).items()}
        for key in ("tracks", "outliers", "nis_mean"):
            res[key] = kv.get(f"radar_io.tracking.{key}", "")
        res["parquet_mb"] = out.stat().st_size / 1e6
        res["warm_us_per_row"] = res["warm_s"] / res["rows"] * 1e6
        if importlib.util.find_spec("stonesoup") is None:
            res["stonesoup"] = "not installed (pip install stonesoup): anchor skipped"
        else:
            p = subprocess.run([sys.executable, "-m", "radar_io.benchmarks.tracking",
                                "--anchor", str(rec)], check=True, capture_output=True)
            anchor = json.loads(p.stdout)
            res["stonesoup_us_per_measurement"] = anchor["s_per_measurement"] * 1e6
            res["speedup_vs_stonesoup"] = (anchor["s_per_measurement"]
                                           / (res["warm_s"] / res["rows"]))
        out.unlink(missing_ok=True)
    finally:
        if env_before is None:
            os.environ.pop("NUMBA_CACHE_DIR", None)
        else:
            os.environ["NUMBA_CACHE_DIR"] = env_before
        shutil.rmtree(cache, ignore_errors=True)
        if not keep and workdir is None:
            shutil.rmtree(tmp, ignore_errors=True)
    return res


def live_cost(frames: int = 20_000, sizes: tuple[int, ...] = (1, 5, 20)) -> dict[str, Any]:
    """The live pipeline's processing time per chunk (framing, decoding, the filter, JSON
    into the history) with and without the tracking filter, simulator frames at 1 kHz
    fed in chunks of ``sizes`` frames; and the filter's start cost (numba's cache load, or
    compilation on a machine's first start) in a fresh process."""
    import numpy as np

    from radar_io.service.history import History
    from radar_io.service.pipeline import Pipeline
    from radar_io.simulation.radar import RadarSimulator, SimConfig
    from radar_io.tracking.live import warm_up
    from radar_io.tracking.tracker import TrackParams
    from radar_io.wirespec.frame import load_spec

    code = ("import time; t = time.perf_counter(); from radar_io.tracking.live import warm_up;"
            " i = time.perf_counter() - t; print(i, warm_up())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    import_s, warm_s = (float(v) for v in out.stdout.split())
    warm_up()
    spec = load_spec()
    sim = RadarSimulator(config=SimConfig(seed=1, rate_hz=1000.0, go_delay_s=0.0))
    data, _ = sim.generate(frames)
    res: dict[str, Any] = {"frames": frames, "start_import_s": import_s, "start_warm_up_s": warm_s,
                           "loadavg": os.getloadavg()}
    for per in sizes:
        med: dict[str, float] = {}
        for name, track in (("off", None), ("on", TrackParams())) * 2:
            pipe = Pipeline("loop://", spec, History(256 << 20), lambda items: None, track=track)
            ts = []
            for k in range(0, frames, per):
                chunk = data[24 * k:24 * (k + per)]
                t0 = time.perf_counter_ns()
                pipe._process(chunk, 0, 0)
                ts.append(time.perf_counter_ns() - t0)
            m = float(np.median(ts[len(ts) // 10:])) / 1e3  # µs, after the first tenth
            med[name] = min(med.get(name, m), m)  # the better of two runs each
        res[f"chunk{per}_off_us"], res[f"chunk{per}_on_us"] = med["off"], med["on"]
        res[f"chunk{per}_filter_us_per_frame"] = (med["on"] - med["off"]) / per
    return res


def live_report(res: dict[str, Any]) -> str:
    lines = [f"live tracking filter: start {res['start_warm_up_s']:.2f} s (numba kernels "
             f"loaded or compiled; imports {res['start_import_s']:.2f} s), load average "
             f"{res['loadavg'][0]:.1f}; median processing per chunk without / with the filter:"]
    for k in res:
        if k.endswith("_off_us"):
            per = k[5:-7]
            lines.append(f"  {per} frame(s) per chunk: {res[k]:.1f} / "
                         f"{res[f'chunk{per}_on_us']:.1f} us -> "
                         f"{res[f'chunk{per}_filter_us_per_frame']:.1f} us per frame")
    return "\n".join(lines)


def report(res: dict[str, Any]) -> str:
    lines = [
        (f"tracking: {res['hours']} h at 1 kHz ({res['recording_mb']:.0f} MB, {res['rows']:,} "
         "rows) -> smoothed Parquet, fresh process each, radar-io track end to end:"),
        (f"  first run (numba compiles) {res['cold_s']:.1f} s wall {res['cold_cpu_s']:.1f} s "
         f"CPU, peak RSS {res['cold_rss_mb']:.0f} MB"),
        (f"  later runs (compiled code cached) {res['warm_s']:.1f} s wall "
         f"{res['warm_cpu_s']:.1f} s CPU, peak RSS {res['warm_rss_mb']:.0f} MB "
         f"(goal <= 20 s, <= 1024 MB); {res['warm_us_per_row']:.2f} us per row; "
         f"{res['tracks']} tracks, {res['outliers']} outliers, NIS mean {res['nis_mean']}"),
    ]
    if "speedup_vs_stonesoup" in res:
        lines.append(f"  Stone Soup EKF + RTS smoother: {res['stonesoup_us_per_measurement']:.0f} us "
                     f"per measurement -> {res['speedup_vs_stonesoup']:.0f}x (goal >= 100x)")
    else:
        lines.append(f"  Stone Soup: {res['stonesoup']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m radar_io.benchmarks.tracking",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--hours", type=float, default=1.0)
    p.add_argument("--workdir", help="keep the recording here (reused on the next run)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--live", action="store_true", help="the live filter's cost per chunk only")
    p.add_argument("--anchor", metavar="REC", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.anchor:
        print(json.dumps(stonesoup_anchor(args.anchor)))
        return 0
    if args.live:
        res = live_cost()
        print(json.dumps(res, indent=2) if args.json else live_report(res))
        return 0
    res = run(args.hours, args.workdir, keep=args.workdir is not None)
    print(json.dumps(res, indent=2) if args.json else report(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
