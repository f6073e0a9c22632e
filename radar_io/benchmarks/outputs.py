"""End-to-end output benchmark: ``radar-io decode`` → Parquet / CSV beside pyarrow anchors.

``python -m radar_io.benchmarks.outputs [--hours 1] [--long-hours 10]``

1. Simulates a recording of ``--hours`` at 1 kHz (``radar-io simulate``) in a temporary
   directory.
2. Runs, each in a fresh child process timed from outside (interpreter start and imports
   included in every figure, so they compare like with like):

   * ``radar-io decode REC -o out.parquet`` and ``-o out.csv`` (the CLI, streaming);
   * the anchors: read all payloads + one numpy ``decode_bytes`` +
     ``pyarrow.parquet.write_table`` (zstd), and the same with ``pyarrow.csv.write_csv``
     — the whole recording in memory, nothing streamed, no temp file, no metadata.

   Each figure is the best of ``--repeat`` runs; peak RSS is the child's ``ru_maxrss``.
3. With ``--long-hours`` > 0, a longer recording (the 1-h payload repeated) is decoded
   to Parquet by the CLI once, to show the peak RSS does not grow with the input
   (``--archive``: and archived by ``radar-io archive``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any


def _run_child(args: list[str]) -> tuple[float, float, float]:
    """Run ``python args…``; (wall s, CPU s = user + system, peak RSS MB). Raises if it fails."""
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, *args], stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE)
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    err = p.stderr.read().decode() if p.stderr else ""
    if p.stderr:
        p.stderr.close()
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({p.returncode}): {err.strip()}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def _best(args: list[str], repeat: int) -> tuple[float, float, float]:
    """Best wall and best CPU time of ``repeat`` runs, and the largest peak RSS."""
    runs = [_run_child(args) for _ in range(repeat)]
    return min(r[0] for r in runs), min(r[1] for r in runs), max(r[2] for r in runs)


def anchor(fmt: str, src: str, out: str) -> None:
    """The anchor: whole payload in memory, one numpy decode, one pyarrow write.

    ``fmt`` ``parquet+fsync`` / ``csv+fsync``: the same, then fsync the output (the CLI
    fsyncs before its rename; this anchor has the same durability).
    """
    import pyarrow as pa

    fmt, _, sync = fmt.partition("+")
    from radar_io.decoding.batch_decoder import decode_bytes
    from radar_io.recording.rdrlog import iter_payloads

    data = b"".join(iter_payloads(src))
    b = decode_bytes(data)
    del data
    table = pa.table({c: b[c] for c in b.columns})
    if fmt == "parquet":
        import pyarrow.parquet as pq

        pq.write_table(table, out, compression="zstd")
    else:
        import pyarrow.csv as pcsv

        pcsv.write_csv(table, out)
    if sync:
        fd = os.open(out, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def make_recording(path: Path, hours: float) -> float:
    """Simulate ``hours`` at 1 kHz into ``path``; returns the seconds it took."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "radar_io.cli", "simulate", "-o", str(path),
                    "--duration-s", str(hours * 3600.0), "-q"], check=True)
    return time.perf_counter() - t0


def repeat_recording(src: Path, dst: Path, times: int) -> None:
    """A recording holding ``src``'s chunks ``times`` over (receive times shifted)."""
    from radar_io.recording.rdrlog import RecordingReader, RecordingWriter, encode_chunk
    from radar_io.wirespec.frame import load_spec

    with RecordingReader(src) as r:
        chunks = [(c.t_ns, c.mono_ns, c.data) for c in r]
    span = chunks[-1][1] - chunks[0][1] + 1
    RecordingWriter(dst, load_spec(), fsync_interval_s=3600).close()  # header only
    with open(dst, "ab") as f:
        for k in range(times):
            f.write(b"".join(encode_chunk(d, t + k * span, m + k * span) for t, m, d in chunks))


def run(hours: float = 1.0, long_hours: float = 10.0, repeat: int = 2,
        workdir: str | None = None, keep: bool = False, archive: bool = False) -> dict[str, Any]:
    tmp = Path(workdir or tempfile.mkdtemp(prefix="radar-io-bench-outputs-"))
    tmp.mkdir(parents=True, exist_ok=True)
    res: dict[str, Any] = {"hours": hours, "repeat": repeat}
    try:
        rec = tmp / "hour.rdrlog"
        if not rec.exists():
            res["simulate_s"] = make_recording(rec, hours)
        res["recording_mb"] = rec.stat().st_size / 1e6
        me = "radar_io.benchmarks.outputs"
        for fmt in ("parquet", "csv"):
            out = tmp / f"cli.{fmt}"
            res[f"cli_{fmt}_s"], res[f"cli_{fmt}_cpu_s"], res[f"cli_{fmt}_rss_mb"] = _best(
                ["-m", "radar_io.cli", "decode", str(rec), "-o", str(out), "-q"], repeat)
            res[f"{fmt}_mb"] = out.stat().st_size / 1e6
            res[f"anchor_{fmt}_s"], res[f"anchor_{fmt}_cpu_s"], res[f"anchor_{fmt}_rss_mb"] = \
                _best(["-m", me, "--anchor", fmt, str(rec), str(tmp / f"anchor.{fmt}")], repeat)
            res[f"ratio_{fmt}"] = res[f"cli_{fmt}_s"] / res[f"anchor_{fmt}_s"]
            res[f"ratio_{fmt}_cpu"] = res[f"cli_{fmt}_cpu_s"] / res[f"anchor_{fmt}_cpu_s"]
            res[f"anchor_{fmt}_fsync_s"], _, _ = _best(
                ["-m", me, "--anchor", f"{fmt}+fsync", str(rec), str(tmp / f"anchor.{fmt}")],
                repeat)
            res[f"ratio_{fmt}_fsync"] = res[f"cli_{fmt}_s"] / res[f"anchor_{fmt}_fsync_s"]
            for p in (out, tmp / f"anchor.{fmt}"):
                p.unlink(missing_ok=True)
        if long_hours > 0:
            times = max(1, round(long_hours / hours))
            big = tmp / "long.rdrlog"
            # in a child: the parent stays small, since a child's ru_maxrss includes the
            # parent's RSS at fork/exec time
            subprocess.run([sys.executable, "-m", me, "--repeat-recording", str(rec), str(big),
                            str(times)], check=True)
            res["long_hours"] = hours * times
            res["long_recording_mb"] = big.stat().st_size / 1e6
            res["cli_long_parquet_s"], res["cli_long_parquet_cpu_s"], \
                res["cli_long_parquet_rss_mb"] = _run_child(
                ["-m", "radar_io.cli", "decode", str(big), "-o", str(tmp / "long.parquet"),
                 "-q"])
            (tmp / "long.parquet").unlink(missing_ok=True)
            if archive:
                res["archive_long_s"], res["archive_long_cpu_s"], res["archive_long_rss_mb"] = \
                    _run_child(["-m", "radar_io.cli", "archive", str(big), "--out",
                                str(tmp / "archive"), "-q"])
                shutil.rmtree(tmp / "archive", ignore_errors=True)
            big.unlink()
    finally:
        if not keep and workdir is None:
            shutil.rmtree(tmp, ignore_errors=True)
    return res


def report(res: dict[str, Any]) -> str:
    lines = [f"recording: {res['hours']} h at 1 kHz, {res['recording_mb']:.0f} MB "
             f"(best of {res['repeat']}, fresh process each; wall and CPU = user + sys)"]
    for fmt in ("parquet", "csv"):
        lines.append(
            f"  {fmt:8s} CLI {res[f'cli_{fmt}_s']:6.2f} s wall {res[f'cli_{fmt}_cpu_s']:6.2f} s CPU "
            f"RSS {res[f'cli_{fmt}_rss_mb']:4.0f} MB | anchor {res[f'anchor_{fmt}_s']:6.2f} s wall "
            f"{res[f'anchor_{fmt}_cpu_s']:6.2f} s CPU RSS {res[f'anchor_{fmt}_rss_mb']:4.0f} MB | "
            f"ratio {res[f'ratio_{fmt}']:.2f}x wall, {res[f'ratio_{fmt}_cpu']:.2f}x CPU "
            f"(goal <= 1.5x)\n{'':11s}anchor + fsync of its output {res[f'anchor_{fmt}_fsync_s']:6.2f} s "
            f"wall: ratio {res[f'ratio_{fmt}_fsync']:.2f}x wall")
    if "long_hours" in res:
        lines.append(f"  {res['long_hours']:.0f} h ({res['long_recording_mb']:.0f} MB) -> parquet: "
                     f"{res['cli_long_parquet_s']:.1f} s wall, "
                     f"{res['cli_long_parquet_cpu_s']:.1f} s CPU, peak RSS "
                     f"{res['cli_long_parquet_rss_mb']:.0f} MB (goal <= 256 MB)")
    if "archive_long_s" in res:
        lines.append(f"  radar-io archive of the {res['long_hours']:.0f}-h recording: "
                     f"{res['archive_long_s']:.1f} s wall, {res['archive_long_cpu_s']:.1f} s CPU, "
                     f"peak RSS {res['archive_long_rss_mb']:.0f} MB")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m radar_io.benchmarks.outputs",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--hours", type=float, default=1.0)
    p.add_argument("--long-hours", type=float, default=10.0, help="0: skip the long file")
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--workdir", help="keep the recordings here (reused on the next run)")
    p.add_argument("--archive", action="store_true",
                   help="also time `radar-io archive` of the long recording (peak RSS)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--anchor", nargs=3, metavar=("FMT", "IN", "OUT"), help=argparse.SUPPRESS)
    p.add_argument("--repeat-recording", nargs=3, metavar=("SRC", "DST", "N"),
                   help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.repeat_recording:
        src, dst, n = args.repeat_recording
        repeat_recording(Path(src), Path(dst), int(n))
        return 0
    if args.anchor:
        anchor(*args.anchor)
        return 0
    res = run(args.hours, args.long_hours, args.repeat, args.workdir, archive=args.archive)
    print(json.dumps(res, indent=2) if args.json else report(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
