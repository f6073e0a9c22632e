"""Strip charts in headless Chromium: a decoded column against time, drawn by the vendored
uPlot, several at once, the choice kept across reloads."""

from __future__ import annotations

from .liveserver import browser, ink_js, sim_server  # noqa: F401
from .test_live_pty import ARTIFACTS

CHART_CANVAS = "radarStrip.charts[{col!r}] && radarStrip.charts[{col!r}].ctx.canvas"


def choose(page, column: str) -> None:
    page.wait_for(f"radarStrip.available.includes({column!r})", 10)
    page.eval(f"document.getElementById('strip-col').value = {column!r}, "
              "document.getElementById('strip-add').click(), true")


def test_strip_chart_shows_the_chosen_columns_and_remembers_them(sim_server, browser):  # noqa: F811
    browser.navigate(sim_server.base + "/")
    browser.eval("localStorage.removeItem('radar_io_strip_columns'), true")
    browser.navigate(sim_server.base + "/")
    # the list offers the live messages' numeric columns
    browser.wait_for("radarStrip.available.length > 10", 15)
    available = browser.eval("radarStrip.available")
    assert {"sr_m", "el_deg", "az_deg", "x_m"} <= set(available)
    assert "msg_seq" not in available and "t_ns" not in available

    choose(browser, "sr_m")
    choose(browser, "el_deg")
    for col in ("sr_m", "el_deg"):
        browser.wait_for(f"radarStrip.charts[{col!r}].data[0].length > 30", 15)
        # the chart's series is that column over the kept messages, against receive time
        got = browser.eval(f"""(() => {{ const u = radarStrip.charts[{col!r}];
            return {{label: u.series[1].label, t: Array.from(u.data[0]), y: Array.from(u.data[1]),
                     seq: radarStrip.messages.slice(0, u.data[0].length).map(m => m.msg_seq)}}; }})()""")
        assert got["label"] == col
        assert len(got["y"]) > 30
        # the same values the service holds for those messages (its track history; the
        # websocket is decimated to 25 Hz, so the chart holds every n-th message): the last 30
        seq, t, y = got["seq"][-30:], got["t"][-30:], got["y"][-30:]
        track = {m["msg_seq"]: m for m in sim_server.get(
            f"/api/track?since={seq[0] - 1}&limit={min(seq[-1] - seq[0] + 1, 20000)}")["messages"]}
        assert set(seq) <= set(track), "chart points the service does not know"
        assert y == [track[s][col] for s in seq]
        assert t == [track[s]["t_ns"] / 1e9 for s in seq]
        assert browser.eval(ink_js(CHART_CANVAS.format(col=col))) > 200  # the line is drawn
    assert browser.eval("document.querySelectorAll('#strip-charts .strip').length") == 2
    browser.eval("document.getElementById('strip').scrollIntoView(), true")
    browser.screenshot(ARTIFACTS / "dashboard-stripcharts.png")

    # remembered after a reload, drawn again from fresh data
    browser.navigate(sim_server.base + "/")
    assert browser.eval("radarStrip.columns") == ["sr_m", "el_deg"]
    browser.wait_for("radarStrip.draws > 2", 15)
    browser.wait_for(ink_js(CHART_CANVAS.format(col="el_deg")) + " > 200", 10)

    # removing one is remembered too
    browser.eval("document.querySelector('#strip-charts .strip[data-column=sr_m] button').click(), true")
    assert browser.eval("radarStrip.columns") == ["el_deg"]
    browser.navigate(sim_server.base + "/")
    assert browser.eval("Object.keys(radarStrip.charts)") == ["el_deg"]
    browser.screenshot(ARTIFACTS / "dashboard-stripchart-reloaded.png")
