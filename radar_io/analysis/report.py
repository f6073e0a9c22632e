"""Flight report: figures and tables of one recording, as self-contained HTML or a PDF.

Figures (matplotlib, Agg backend, decimated to a few thousand points each):

1. plan view (Y east → right, X north → up) with range rings and the reference path;
2. height H vs ground range R = sqrt(X² + Y²), with the path;
3. DY and DZ vs along-track distance (the pen-recorder chart; needs a path);
4. SR / EL / AZ and the servo errors ΔSR / ΔEL / ΔAZ vs time;
5. CRC errors and SEQ gaps (cumulative) on the timeline, with GO and RX GOOD;
6. pressure altitude − radar height vs time (needs an airborne CAN log);
7. the best estimate of trajectory (BET, :mod:`radar_io.analysis.bet_page`): smoothed
   track with ±3σ bands, residuals with ±3σ, NIS over time, with its table and outliers.

Annotations (notes, markers, test points) are drawn on the time plots (4, 5 and, with a
path, DY / DZ vs time), test points shaded.

Tables: the summary (duration, frames, CRC errors, gaps, GO time, RX GOOD fraction,
DY / DZ RMS and max |.| per leg), the test points (span, DY / DZ RMS and max |.| each),
the annotations, the alarm events of the recording's event log
(``<id>.events.jsonl``, when there is one) and the sync events with their times.

HTML embeds every figure as a base64 PNG (no external file, no script, no CDN);
PDF is written with :class:`matplotlib.backends.backend_pdf.PdfPages`, one figure
per page, then the tables.
"""

from __future__ import annotations

import base64
import html
import io
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from radar_io.analysis.flight_digest import FlightDigest
from radar_io.errors import ConfigError

FORMATS = ("html", "pdf")


@dataclass
class Report:
    """Built figures (matplotlib ``Figure`` objects with titles) and tables of one digest."""

    digest: FlightDigest
    figures: list[tuple[str, Any]] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)
    legs: list[dict[str, Any]] = field(default_factory=list)
    sync_events: list[dict[str, Any]] = field(default_factory=list)
    airdata: dict[str, Any] | None = None
    bet: Any = None  #: a :class:`~radar_io.analysis.bet_page.BetPage` (None: no good data)

    def close(self) -> None:
        import matplotlib.pyplot as plt

        for _, fig in self.figures:
            plt.close(fig)
        self.figures.clear()


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _path_radar_polyline(d: FlightDigest, step_m: float = 50.0) -> tuple[np.ndarray, ...] | None:
    """The reference path in the radar frame (x, y, h), or None."""
    p = d.path
    if p is None:
        return None
    s = np.append(np.arange(0.0, p.length_m, step_m), p.length_m)
    x, y, h = p.position(s)
    if p.frame == "runway":
        from radar_io.coordinates.transforms import runway_to_radar

        assert d.site is not None  # digest_recording refuses a runway-frame path without it
        x, y, h = runway_to_radar(x, y, h, d.site)
    return np.asarray(x), np.asarray(y), np.asarray(h)


def _fig_plan(d: FlightDigest) -> Any:
    plt = _plt()
    c = d.columns
    i = d.plot_index()
    x, y = c["x_m"][i], c["y_m"][i]
    fig, ax = plt.subplots(figsize=(8, 7))
    ax.plot(y / 1e3, x / 1e3, ".", ms=1.5, color="tab:blue", label="radar track", rasterized=True)
    poly = _path_radar_polyline(d)
    rmax = float(np.nanmax(np.hypot(x, y))) if np.isfinite(x).any() else 1000.0
    if poly is not None:
        ax.plot(poly[1] / 1e3, poly[0] / 1e3, "-", color="tab:red", lw=1.2, label="reference path")
        rmax = max(rmax, float(np.max(np.hypot(poly[0], poly[1]))))
    ring = 5000.0 if rmax > 10000 else 1000.0
    a = np.linspace(0, 2 * np.pi, 361)
    for r in np.arange(ring, rmax + ring, ring):
        ax.plot(r / 1e3 * np.sin(a), r / 1e3 * np.cos(a), color="0.8", lw=0.7, zorder=0)
        ax.annotate(f"{r / 1e3:g} km", (0, r / 1e3), color="0.5", fontsize=7, ha="center")
    ax.plot([0], [0], "k^", label="radar")
    ax.set_aspect("equal")
    ax.set_xlabel("Y east [km]")
    ax.set_ylabel("X north [km]")
    ax.set_title("Plan view (radar frame) with range rings")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig


def _fig_height(d: FlightDigest) -> Any:
    plt = _plt()
    c = d.columns
    i = d.plot_index()
    fig, ax = plt.subplots(figsize=(10, 4.5))
    ax.plot(np.hypot(c["x_m"][i], c["y_m"][i]) / 1e3, c["h_m"][i], ".", ms=1.5,
            label="radar H", rasterized=True)
    poly = _path_radar_polyline(d)
    if poly is not None:
        ax.plot(np.hypot(poly[0], poly[1]) / 1e3, poly[2], "-", color="tab:red", lw=1.2,
                label="reference path")
    ax.set_xlabel("ground range R [km]")
    ax.set_ylabel("H above antenna [m]")
    ax.set_title("Height vs ground range")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _fig_deviation(d: FlightDigest) -> Any:
    plt = _plt()
    c = d.columns
    i = d.plot_index(6000)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    along = c["along_m"][i] / 1e3
    a1.plot(along, c["dy_m"][i], lw=0.6, color="tab:blue", rasterized=True)
    a1.set_ylabel("DY right of path [m]")
    a2.plot(along, c["dz_m"][i], lw=0.6, color="tab:green", rasterized=True)
    a2.set_ylabel("DZ above path [m]")
    a2.set_xlabel("along-track distance [km]")
    for a in (a1, a2):
        a.axhline(0, color="k", lw=0.5)
        a.grid(alpha=0.3)
    a1.set_title("Deviation from the reference path")
    return fig


def _mark_annotations(axes: Any, d: FlightDigest) -> None:
    """Annotations as vertical lines on time axes (``t_s``), labelled on the first axis;
    test points shaded from start to end."""
    axes = list(np.ravel(axes))
    for tp in d.test_points():
        for a in axes:
            a.axvspan(tp["from_s"], tp["to_s"], color="tab:purple", alpha=0.08, lw=0)
    for e in d.annotations:
        for a in axes:
            a.axvline(e["t_s"], color="tab:purple", lw=0.8, ls="--")
        axes[0].annotate(str(e.get("label") or e.get("annotation_kind", "")), (e["t_s"], 1),
                         xycoords=("data", "axes fraction"), fontsize=7, color="tab:purple",
                         rotation=90, va="top", ha="right")


def _fig_deviation_time(d: FlightDigest) -> Any:
    """DY and DZ vs time with the test points marked."""
    plt = _plt()
    c = d.columns
    i = d.plot_index(6000)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    a1.plot(c["t_s"][i], c["dy_m"][i], lw=0.6, color="tab:blue", rasterized=True)
    a1.set_ylabel("DY [m]")
    a2.plot(c["t_s"][i], c["dz_m"][i], lw=0.6, color="tab:green", rasterized=True)
    a2.set_ylabel("DZ [m]")
    a2.set_xlabel("time from first frame [s]")
    for a in (a1, a2):
        a.axhline(0, color="k", lw=0.5)
        a.grid(alpha=0.3)
    _mark_annotations((a1, a2), d)
    a1.set_title("DY and DZ vs time, test points shaded")
    return fig


def _fig_angles(d: FlightDigest) -> Any:
    plt = _plt()
    c = d.columns
    i = d.plot_index()
    t = c["t_s"][i]
    fig, axes = plt.subplots(3, 2, figsize=(11, 7.5), sharex=True)
    for row, (main, err, unit) in enumerate((("sr_m", "dsr_m", "m"), ("el_deg", "del_deg", "deg"),
                                             ("az_deg", "daz_deg", "deg"))):
        name = main.split("_")[0].upper()
        axes[row, 0].plot(t, c[main][i], lw=0.7, rasterized=True)
        axes[row, 0].set_ylabel(f"{name} [{unit}]")
        axes[row, 1].plot(t, c[err][i], lw=0.7, color="tab:orange", rasterized=True)
        axes[row, 1].set_ylabel(f"Δ{name} servo error [{unit}]")
        for a in axes[row]:
            a.grid(alpha=0.3)
    for a in axes[-1]:
        a.set_xlabel("time from first frame [s]")
    _mark_annotations(axes, d)
    fig.suptitle("Radar measurements and servo errors vs time")
    fig.tight_layout()
    return fig


def _fig_link(d: FlightDigest) -> Any:
    plt = _plt()
    c = d.columns
    i = d.plot_index()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 5), sharex=True,
                                 gridspec_kw={"height_ratios": [2, 1]})
    a1.step(d.counter_t_s, d.counter_crc, where="post", label="CRC errors (cumulative)")
    a1.step(d.counter_t_s, d.counter_gaps, where="post", label="SEQ gaps (cumulative)")
    jumps = d.seq_jump_t_s[np.isfinite(d.seq_jump_t_s)]
    if jumps.size:
        a1.plot(jumps, np.zeros(jumps.size), "|", color="tab:red", ms=12,
                label="SEQ discontinuity")
    a1.set_ylabel("count")
    a1.legend(fontsize=8, loc="upper left")
    a1.grid(alpha=0.3)
    a1.set_title("Link health: CRC errors and SEQ gaps")
    # flags reduced by block minimum: a dropout shorter than the plotting step still shows
    step = d.stride * (int(i[1] - i[0]) if i.size > 1 else 1)
    go, good = (np.minimum.reduceat(d.flag_min[k], i) for k in ("go", "rx_good"))
    a2.step(c["t_s"][i], go + 1.5, where="post", label="GO (upper)")
    a2.step(c["t_s"][i], good, where="post", label="RX GOOD (lower)")
    a2.set_yticks([0, 1, 1.5, 2.5], ["0", "1", "0", "1"])
    a2.set_title(f"GO and RX GOOD (minimum over {step} frames)", fontsize=9)
    a2.set_xlabel("time from first frame [s]")
    a2.legend(fontsize=8, loc="center right")
    a2.grid(alpha=0.3)
    _mark_annotations((a1, a2), d)
    return fig


def _fig_airdata(alt: dict[str, np.ndarray], tod0_s: float) -> Any:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(alt["tod_s"] - tod0_s, alt["difference_m"], ".", ms=2, label="PA − radar H")
    if "expected_m" in alt:
        ax.plot(alt["tod_s"] - tod0_s, alt["expected_m"], "-", lw=0.8, label="expected")
    ax.set_xlabel("time from first frame [s]")
    ax.set_ylabel("pressure altitude − radar H [m]")
    ax.set_title("Air data: pressure altitude − radar height")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _airdata(d: FlightDigest, can_log: str | os.PathLike[str], dbc: Any = None
             ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Align the CAN log to the radar's sync edges; PA − H per 8 Hz sample. The radar track
    at full rate comes from a second pass over the recording (as ``radar-io align``)."""
    from radar_io.analysis.clock_alignment import compare_altitude, fit_clock, radar_track
    from radar_io.decoding.airdata import load_dbc, read_can_log
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import iter_payloads

    track = radar_track(iter_decode(iter_payloads(d.source), **d.decode_options))
    log = read_can_log(can_log, load_dbc(dbc))
    fit = fit_clock(track.edge_s, log.event_time_s, log.event_count,
                    frame_period_s=track.frame_period_s)
    alt = compare_altitude(fit, log, track)
    diff = alt["difference_m"]
    info = {"file": str(can_log), "samples": int(diff.size), "clock_offset_s": fit.offset_s,
            "drift_ppm": fit.drift_ppm, "matched_events": int(fit.radar_index.size),
            "mean_m": float(diff.mean()) if diff.size else None,
            "std_m": float(diff.std()) if diff.size else None}
    return alt, info


def build_report(d: FlightDigest, *, airdata: str | os.PathLike[str] | None = None,
                 dbc: Any = None, bet: bool = True) -> Report:
    """All figures and tables of a digest (``bet``: with the BET page, a second pass)."""
    rep = Report(d, summary=d.summary(), legs=d.legs(), sync_events=d.sync_events())
    rep.figures.append(("Plan view", _fig_plan(d)))
    rep.figures.append(("Height vs range", _fig_height(d)))
    if "dy_m" in d.columns:
        rep.figures.append(("DY and DZ vs along-track distance", _fig_deviation(d)))
        if d.annotations:
            rep.figures.append(("DY and DZ vs time, with the annotations",
                                _fig_deviation_time(d)))
    rep.figures.append(("SR / EL / AZ and servo errors", _fig_angles(d)))
    rep.figures.append(("CRC errors and SEQ gaps", _fig_link(d)))
    if bet:
        from radar_io.analysis import bet_page

        rep.bet = bet_page.build_bet(d)
        if rep.bet is not None:
            rep.figures += bet_page.figures(rep.bet)
    if airdata is not None:
        alt, info = _airdata(d, airdata, dbc)
        rep.airdata = info
        tod0 = float(d.columns["tod_s"][0])
        rep.figures.append(("Pressure altitude − radar height", _fig_airdata(alt, tod0)))
    return rep


def _bet_tables(rep: Report) -> list[tuple[str, tuple[str, ...] | None, list[tuple[str, ...]]]]:
    """(title, head, rows) of the BET page's tables."""
    from radar_io.analysis import bet_page

    if rep.bet is None:
        return []
    cal = rep.digest.decode_options.get("calibration")
    return [("Best estimate of trajectory", None, bet_page.summary_rows(rep.bet, cal)),
            (f"BET outliers ({rep.bet.summary['tracking.outliers']}; first "
             f"{bet_page.MAX_OUTLIER_ROWS} listed)", bet_page.OUTLIER_HEAD,
             bet_page.outlier_rows(rep.bet))]


# --------------------------------------------------------------------------- tables
def _summary_rows(rep: Report) -> list[tuple[str, str]]:
    s = rep.summary
    rows = [("recording", os.path.basename(rep.digest.source)),
            ("duration", f"{s['duration_s']:.1f} s"), ("frames", f"{s['frames']}"),
            ("CRC errors", f"{s['crc_errors']}"), ("SEQ gaps", f"{s['seq_gaps']}"),
            ("bytes discarded", f"{s['bytes_discarded']}"),
            ("GO time", f"{s['go_time_s']:.1f} s"),
            ("RX GOOD fraction", f"{s['rx_good_fraction']:.4f}"),
            ("sync events", f"{s['sync_events']}")]
    if rep.digest.site is not None:
        rows.append(("site", rep.digest.site.name))
    if rep.digest.path is not None:
        rows.append(("reference path", rep.digest.path.name or "(unnamed)"))
    if rep.airdata:
        a = rep.airdata
        rows.append(("air data", f"{a['samples']} samples, PA − H mean "
                     f"{a['mean_m'] if a['mean_m'] is None else round(a['mean_m'], 2)} m, "
                     f"clock offset {a['clock_offset_s']:.4f} s"))
    for p in rep.digest.problems:
        rows.append(("read problem", p))
    return rows


LEG_HEAD = ("leg", "kind", "along from [m]", "along to [m]", "samples", "DY RMS [m]",
            "DY max |.| [m]", "DZ RMS [m]", "DZ max |.| [m]")
SYNC_HEAD = ("#", "SEQ", "TOD [s]", "t [s]", "RX GOOD", "SR [m]", "EL [deg]", "AZ [deg]")


TP_HEAD = ("test point", "from [s]", "to [s]", "samples", "DY RMS [m]", "DY max |.| [m]",
           "DZ RMS [m]", "DZ max |.| [m]", "text")
NOTE_HEAD = ("t [s]", "time (UTC)", "kind", "label", "text", "by")
ALARM_HEAD = ("time (UTC)", "SEQ", "action", "alarm", "column", "value", "limit")


def _num_text(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return "" if v is None else str(v)


def _alarm_rows(rep: Report) -> list[tuple[str, ...]]:
    return [(str(e.get("time_utc", "")), _num_text(e.get("seq")), str(e.get("action", "")),
             str(e.get("name", e.get("id", ""))), str(e.get("column", "")),
             _num_text(e.get("value")), _num_text(e.get("limit")))
            for e in rep.digest.alarm_events]


def _tp_rows(rep: Report) -> list[tuple[str, ...]]:
    def f(v: float) -> str:
        return "" if not np.isfinite(v) else f"{v:.2f}"

    return [(g["label"], f"{g['from_s']:.1f}", f"{g['to_s']:.1f}", str(g["samples"]),
             f(g["dy_rms_m"]), f(g["dy_max_abs_m"]), f(g["dz_rms_m"]), f(g["dz_max_abs_m"]),
             g["text"]) for g in rep.digest.test_points()]


def _note_rows(rep: Report) -> list[tuple[str, ...]]:
    import time as _time

    def utc(t_ns: int) -> str:
        return _time.strftime("%Y-%m-%d %H:%M:%S", _time.gmtime(t_ns / 1e9)) \
            + f".{t_ns // 1_000_000 % 1000:03d}"

    return [(f"{e['t_s']:.3f}", utc(int(e["t_ns"])), str(e.get("annotation_kind", "")),
             str(e.get("label", "")), str(e.get("text", "")), str(e.get("actor") or ""))
            for e in rep.digest.annotations]


def _leg_rows(rep: Report) -> list[tuple[str, ...]]:
    return [(str(g["leg"]), g["kind"], f"{g['along_from_m']:.0f}", f"{g['along_to_m']:.0f}",
             str(g["samples"]), f"{g['dy_rms_m']:.2f}", f"{g['dy_max_abs_m']:.2f}",
             f"{g['dz_rms_m']:.2f}", f"{g['dz_max_abs_m']:.2f}") for g in rep.legs]


def _sync_rows(rep: Report) -> list[tuple[str, ...]]:
    return [(str(e["index"]), str(e["seq"]), f"{e['tod_s']:.4f}", f"{e['t_s']:.3f}",
             "yes" if e["rx_good"] else "NG", f"{e['sr_m']:.1f}", f"{e['el_deg']:.4f}",
             f"{e['az_deg']:.4f}") for e in rep.sync_events]


# --------------------------------------------------------------------------- output
def _png_b64(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _table(head: tuple[str, ...] | None, rows: Sequence[tuple[str, ...]]) -> str:
    e = html.escape
    out = ["<table>"]
    if head:
        out.append("<tr>" + "".join(f"<th>{e(h)}</th>" for h in head) + "</tr>")
    out += ["<tr>" + "".join(f"<td>{e(v)}</td>" for v in r) + "</tr>" for r in rows]
    out.append("</table>")
    return "\n".join(out)


_CSS = """body{font-family:sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em}
td,th{border:1px solid #bbb;padding:2px 8px;font-size:13px;text-align:right}
th{background:#eee}td:first-child{text-align:left}
figure{margin:1em 0}img{max-width:100%}figcaption{font-weight:bold}"""


def render_html(rep: Report) -> str:
    """The report as one self-contained HTML document (images embedded)."""
    e = html.escape
    name = os.path.basename(rep.digest.source)
    parts = [f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
             f"<title>Flight report {e(name)}</title><style>{_CSS}</style></head><body>",
             f"<h1>Flight report: {e(name)}</h1>", "<h2>Summary</h2>",
             _table(None, _summary_rows(rep))]
    if rep.legs:
        parts += ["<h2>Deviation per leg</h2>", _table(LEG_HEAD, _leg_rows(rep))]
    if rep.digest.test_point_stats:
        parts += [f"<h2>Test points ({len(rep.digest.test_point_stats)})</h2>",
                  _table(TP_HEAD, _tp_rows(rep))]
    if rep.digest.annotations:
        parts += [f"<h2>Annotations ({len(rep.digest.annotations)})</h2>",
                  _table(NOTE_HEAD, _note_rows(rep))]
    if rep.digest.alarm_events:
        parts += [f"<h2>Alarm events ({len(rep.digest.alarm_events)})</h2>",
                  _table(ALARM_HEAD, _alarm_rows(rep))]
    parts += [f"<h2>Sync events ({len(rep.sync_events)})</h2>",
              _table(SYNC_HEAD, _sync_rows(rep)) if rep.sync_events else "<p>none</p>"]
    for title, head, rows in _bet_tables(rep):
        parts += [f"<h2>{e(title)}</h2>", _table(head, rows) if rows else "<p>none</p>"]
    parts.append("<h2>Figures</h2>")
    for title, fig in rep.figures:
        parts.append(f"<figure><figcaption>{e(title)}</figcaption><img alt=\"{e(title)}\" "
                     f"src=\"data:image/png;base64,{_png_b64(fig)}\"></figure>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


def _table_pages(pdf: Any, title: str, head: tuple[str, ...] | None,
                 rows: Sequence[tuple[str, ...]], per_page: int = 40) -> None:
    plt = _plt()
    for k in range(0, max(len(rows), 1), per_page):
        chunk = rows[k:k + per_page] or [("(none)",) + ("",) * (len(head or ("",)) - 1)]
        fig = plt.figure(figsize=(8.27, 11.69))
        fig.text(0.05, 0.96, title + (" (continued)" if k else ""), fontsize=13,
                 weight="bold")
        ax = fig.add_axes((0.03, 0.03, 0.94, 0.9))
        ax.axis("off")
        tab = ax.table(cellText=[list(r) for r in chunk], colLabels=list(head) if head else None,
                       loc="upper center", cellLoc="right")
        tab.auto_set_font_size(False)
        tab.set_fontsize(7)
        pdf.savefig(fig)
        plt.close(fig)


def render_pdf(rep: Report, out: Any) -> int:
    """Write the report as PDF to a path or binary file; returns the page count."""
    from matplotlib.backends.backend_pdf import PdfPages

    pages = 0
    with PdfPages(out, metadata={"Title": f"Flight report {os.path.basename(rep.digest.source)}",
                                 "Creator": "radar_io report"}) as pdf:
        _table_pages(pdf, "Summary", None, _summary_rows(rep))
        if rep.legs:
            _table_pages(pdf, "Deviation per leg", LEG_HEAD, _leg_rows(rep))
        if rep.digest.test_point_stats:
            _table_pages(pdf, "Test points", TP_HEAD, _tp_rows(rep))
        if rep.digest.annotations:
            _table_pages(pdf, "Annotations", NOTE_HEAD, _note_rows(rep))
        if rep.digest.alarm_events:
            _table_pages(pdf, f"Alarm events ({len(rep.digest.alarm_events)})", ALARM_HEAD,
                         _alarm_rows(rep))
        _table_pages(pdf, f"Sync events ({len(rep.sync_events)})", SYNC_HEAD, _sync_rows(rep))
        for title, head, rows in _bet_tables(rep):
            _table_pages(pdf, title, head, rows)
        for _title, fig in rep.figures:
            pdf.savefig(fig)
        pages = pdf.get_pagecount()
    return pages


def report_format(output: str, fmt: str | None = None) -> str:
    """``html`` or ``pdf``, from ``fmt`` or the output file's extension."""
    f = (fmt or os.path.splitext(output)[1].lstrip(".")).lower()
    if f == "htm":
        f = "html"
    if f not in FORMATS:
        raise ConfigError(f"report format must be html or pdf (from -o's extension or "
                          f"--format), got {f or output!r}")
    return f


def write_report(recording: str | os.PathLike[str], output: str | os.PathLike[str] | io.BytesIO,
                 fmt: str = "html", *, site: Any = None, calibration: Any = None,
                 ref_path: Any = None, airdata: str | None = None, spec: Any = None,
                 progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Decode ``recording`` and write its report; returns the summary (+ ``pages`` for PDF)."""
    from radar_io.analysis.flight_digest import digest_recording

    d = digest_recording(recording, site=site, calibration=calibration, ref_path=ref_path,
                         spec=spec, progress=progress)
    rep = build_report(d, airdata=airdata)
    try:
        info: dict[str, Any] = {**rep.summary, "figures": len(rep.figures)}
        if fmt == "pdf":
            info["pages"] = render_pdf(rep, output)
        else:
            text = render_html(rep)
            if isinstance(output, io.BytesIO):
                output.write(text.encode("utf-8"))
            else:
                try:
                    with open(output, "w", encoding="utf-8") as f:
                        f.write(text)
                except OSError as exc:
                    raise ConfigError(f"cannot write {output}: {exc.strerror}") from exc
        return info
    finally:
        rep.close()


def report_bytes(recording: str | os.PathLike[str], fmt: str, site: Any = None,
                 calibration: Any = None, ref_path: Any = None, spec: Any = None) -> bytes:
    """The report as bytes (the service builds it in a worker process: plain arguments)."""
    buf = io.BytesIO()
    write_report(recording, buf, fmt, site=site, calibration=calibration, ref_path=ref_path,
                 spec=spec)
    return buf.getvalue()
