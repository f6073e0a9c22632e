"""The dashboard as ES modules in headless Chromium: every module loads (served as
JavaScript, no build step, nothing from another origin), no console error while live data
flows, one error formatter for failed requests."""

from __future__ import annotations

import re
import urllib.request
from pathlib import Path

from .liveserver import browser, ink_js, sim_server  # noqa: F401
from .test_live_pty import ARTIFACTS

WEB = Path(__file__).resolve().parents[2] / "radar_io" / "web"


def test_every_module_is_served_as_javascript_and_loaded(sim_server, browser):  # noqa: F811
    modules = sorted(p.name for p in (WEB / "js").glob("*.js"))
    assert "main.js" in modules and len(modules) >= 12
    for name in modules:
        with urllib.request.urlopen(f"{sim_server.base}/static/js/{name}", timeout=5) as r:
            assert "javascript" in r.headers["Content-Type"], name
    browser.watch_console()
    browser.navigate(sim_server.base + "/")
    loaded = browser.eval("performance.getEntriesByType('resource').map(e => e.name)")
    loaded_js = {u.rsplit("/", 1)[1] for u in loaded if "/static/js/" in u}
    assert loaded_js == set(modules)  # every module is reached from main.js, none is dead
    assert all(u.startswith(sim_server.base) or u.startswith("data:") for u in loaded)  # no CDN
    assert browser.eval("document.querySelector('script[type=module]').src").endswith("/static/js/main.js")


def test_no_console_error_with_live_data(sim_server, browser):  # noqa: F811
    browser.watch_console()
    browser.navigate(sim_server.base + "/")
    browser.wait_for("radarState.points.length > 20 && radarState.connected", 20)
    browser.wait_for(ink_js("document.getElementById('plan')") + " > 500", 10)
    browser.eval("document.getElementById('strip-col').value = 'sr_m', "
                 "document.getElementById('strip-add').click(), true")
    browser.wait_for("radarStrip.draws > 2", 10)
    browser.screenshot(ARTIFACTS / "dashboard-modules.png")
    browser.eval("1")  # drain pending console events
    assert browser.errors() == []


def test_failed_requests_show_one_formatted_line(sim_server, browser):  # noqa: F811
    browser.navigate(sim_server.base + "/")
    # no token typed: the control request is refused, the message line says why
    browser.eval("document.getElementById('token').value = '', "
                 "document.getElementById('rec-start').click(), true")
    browser.wait_for("document.getElementById('msg').textContent !== ''", 10)
    assert re.match(r"^401: control needs", browser.eval("document.getElementById('msg').textContent"))
    # a pydantic list detail becomes "field: message" instead of raw JSON
    text = browser.eval("""import('/static/js/api.js').then(api => api.request(
        '/api/coordinates/runway-to-radar', {method: 'POST', body: {xr_m: [1], yr_m: [1]}})
        .then(() => 'no error', e => e.message))""")
    assert text.startswith("422: ") and "hr_m" in text and "[{" not in text


def test_api_docs_page_renders_from_the_package_offline(sim_server, browser):  # noqa: F811
    """/docs is Swagger UI from web/vendor (no CDN): it renders the service's operations with
    every resource from the service itself."""
    with urllib.request.urlopen(f"{sim_server.base}/docs", timeout=5) as r:
        html = r.read().decode()
    assert "/static/vendor/swagger-ui/swagger-ui-bundle.js" in html and "cdn." not in html
    browser.watch_console()
    browser.call("Page.enable")
    browser.call("Page.navigate", url=sim_server.base + "/docs")
    browser.wait_for("document.querySelectorAll('.opblock').length > 20", 20)
    assert "radar_io" in browser.eval("document.querySelector('.info .title').textContent")
    loaded = browser.eval("performance.getEntriesByType('resource').map(e => e.name)")
    assert loaded and all(u.startswith(sim_server.base) or u.startswith("data:") for u in loaded)
    assert browser.errors() == []
