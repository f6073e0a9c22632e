"""The FastAPI application: :func:`build_app` assembles the routers around one
:class:`~radar_io.service.state.ServiceState`; its workers (acquisition, sink workers,
air data) start and stop in the lifespan.

Routers, one per concern (``service/routers/``): status, live (track, ws, site, path,
airdata), recordings, series (look-back), replay, calibration, coordinates, runway, alarms,
report, annotations, access (whoami, audit). Roles and the audit trail: :mod:`radar_io.service.auth`,
:mod:`radar_io.service.audit`. Errors: one body shape, radar_io errors mapped by class
(:mod:`radar_io.service.errors`). Host and Origin checks, header and body limits:
:mod:`radar_io.service.guard`; expensive requests: :mod:`radar_io.service.limits`.
"""

from __future__ import annotations

import asyncio
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from radar_io import __version__
from radar_io.service.config import ServiceConfig
from radar_io.service.errors import install_error_handlers, responses
from radar_io.service.guard import GuardMiddleware
from radar_io.service.state import ServiceState

WEB_DIR = Path(__file__).resolve().parent.parent / "web"

#: GIL switch interval: the reader thread and the event loop take turns every 0.5 ms
#: instead of Python's default 5 ms, which would otherwise show up as websocket latency
SWITCH_INTERVAL_S = 0.0005


def build_app(cfg: ServiceConfig) -> FastAPI:
    """The service app for ``cfg``; refuses a configuration that can never work
    (ConfigError) before anything starts. Workers run only inside the lifespan."""
    from radar_io.service.alarms import attach_alarms, status_loop
    from radar_io.service.audit import AuditMiddleware, ReadGuard
    from radar_io.service.lookback import LookBack
    from radar_io.service.routers import (
        access,
        alarms,
        annotations,
        calibration,
        coordinates,
        live,
        recordings,
        replay,
        report,
        runway,
        series,
        status,
    )

    sys.setswitchinterval(SWITCH_INTERVAL_S)
    state = ServiceState(cfg)
    state.alarms = alarm_engine = attach_alarms(state)
    lookback = LookBack(state)  # look-back indexes (routers/series.py)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        state.start(asyncio.get_running_loop())
        lookback.start()  # after the state: it chains onto the recorder's on_closed
        alarm_task = asyncio.create_task(status_loop(state, alarm_engine))
        try:
            yield
        finally:
            alarm_task.cancel()
            state.stop()  # closes the recording: queued for the index, dropped by close()
            lookback.close()

    app = FastAPI(title="radar_io", version=__version__, lifespan=lifespan,
                  docs_url=None, redoc_url=None,  # /docs from vendored files (works offline)
                  responses=responses(403, 413, 421, 422, 431),
                  description="Live tracking-radar data, recordings, replay and calibration. "
                  "Units: metres and degrees; field names carry their unit. Control "
                  "endpoints need `Authorization: Bearer <token>` of a role allowed to use "
                  "them (viewer < operator < admin); each is recorded in the audit trail. "
                  "Every error answers "
                  '`{"detail": [{"loc": [...], "msg": "...", "type": "..."}]}`.')
    app.state.service = state
    app.state.lookback = lookback
    install_error_handlers(app)
    for module in (status, live, recordings, series, replay, calibration, coordinates, alarms,
                   report, annotations, access):
        app.include_router(module.router)
    # the runway router declares its own token dependencies (the manual pose needs none)
    app.include_router(runway.router, responses=responses(401, 403, 429))
    app.mount("/static", StaticFiles(directory=WEB_DIR), name="static")

    @app.get("/docs", include_in_schema=False)
    def api_docs() -> HTMLResponse:
        """Swagger UI from the package (web/vendor/swagger-ui), no CDN: works offline."""
        return get_swagger_ui_html(
            openapi_url="/openapi.json", title="radar_io API",
            swagger_js_url="/static/vendor/swagger-ui/swagger-ui-bundle.js",
            swagger_css_url="/static/vendor/swagger-ui/swagger-ui.css",
            swagger_favicon_url="/static/vendor/swagger-ui/favicon-32x32.png")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(WEB_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    app.add_middleware(AuditMiddleware)  # one record per control request (service/audit.py)
    app.add_middleware(ReadGuard)
    app.add_middleware(GuardMiddleware, allowed_origins=cfg.allowed_origins,
                       max_header_bytes=cfg.max_header_kb << 10,
                       max_body_bytes=cfg.max_body_kb << 10,
                       body_limits={"/api/runway": cfg.max_upload_mb << 20},
                       allowed_hosts=cfg.allowed_hosts, bound_host=cfg.host)
    return app


#: the old name
create_app = build_app
