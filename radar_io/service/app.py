"""The FastAPI application: REST, websocket and the dashboard, around one acquisition pipeline."""

from __future__ import annotations

import asyncio
import re
import secrets
import sys
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import Body, Depends, FastAPI, Header, HTTPException, Query, WebSocket
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field
from starlette.websockets import WebSocketDisconnect

from radar_io import __version__
from radar_io.decoding.biases import Calibration, load_calibration, save_calibration, utc_now_iso
from radar_io.errors import ConfigError, RadarIOError
from radar_io.coordinates.transforms import load_site
from radar_io.wirespec.frame import load_spec
from radar_io.service.acquisition import Acquisition
from radar_io.service.config import TOKEN_ENV, ServiceConfig
from radar_io.service.history import History
from radar_io.service.hub import Hub
from radar_io.recording.recorder import Recorder
from radar_io.sources.replay import ReplaySource

WEB_DIR = Path(__file__).resolve().parent.parent / "web"
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,120}$")


class ReplayRequest(BaseModel):
    recording: str = Field(description="recording id (file name without .rdrlog)")
    speed: float = Field(1.0, ge=0.0, le=1000.0, description="× recorded pace; 0 = as fast as possible")


class SeekRequest(BaseModel):
    position_s: float = Field(ge=0.0, description="seconds from the recording's start")


class StepRequest(BaseModel):
    n: int = Field(1, ge=1, le=100000, description="recorded chunks to deliver")


class SpeedRequest(BaseModel):
    speed: float = Field(ge=0.0, le=1000.0)


class PhotoObservation(BaseModel):
    """A photo position (from resection) at a sync event of a recording."""

    group: str = Field(description="flight / group name for the per-group statistics")
    recording: str = Field(description="recording id holding the sync event")
    sync_index: int = Field(ge=0, description="0-based index of the SYNC 0→1 edge in the recording")
    photo_x_m: float | None = Field(None, description="north of the radar (ground frame)")
    photo_y_m: float | None = Field(None, description="east of the radar")
    photo_z_m: float | None = Field(None, description="down (Z = −H)")
    photo_sr_m: float | None = None
    photo_el_deg: float | None = None
    photo_az_deg: float | None = None


class BiasRequest(BaseModel):
    id: str = Field(description="id of the calibration set to propose")
    observations: list[PhotoObservation] = Field(min_length=1)


class Service:
    """Everything the routes share."""

    def __init__(self, cfg: ServiceConfig) -> None:
        self.cfg = cfg
        self.token = cfg.token()
        self.data_dir = Path(cfg.data_dir)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.spec = load_spec(cfg.spec) if cfg.spec else load_spec()
        site_path = cfg.resolved_site()
        self.site = load_site(site_path) if site_path else None
        self.cal_dir = self.data_dir / "calibrations"
        self.cal_dir.mkdir(exist_ok=True)
        cal = Calibration()
        if cfg.calibration:
            cal = load_calibration(cfg.calibration)
        elif (self.cal_dir / "active.json").exists():
            cal = load_calibration(self.cal_dir / "active.json")
        self.history = History(cfg.history_size)
        self.hub = Hub(self.history, cfg.ws_queue_size)
        self.recorder = Recorder(self.data_dir, self.spec, self.site, cfg.source,
                                 auto=cfg.auto_record, preroll_s=cfg.preroll_s)
        self.acq = Acquisition(cfg.source, self.spec, self.recorder, self.history,
                               self.hub.publish_threadsafe, site=self.site, calibration=cal)
        self.replay: ReplaySource | None = None
        self._setup_outputs(cfg)
        from radar_io.service.alarms import attach_alarms

        self.alarms = attach_alarms(self)
        self.instance = secrets.token_hex(8)  # changes at every start: clients detect restarts

    def _setup_outputs(self, cfg: ServiceConfig) -> None:
        """Reference path, TLM1 / D/A sinks and CAN air data, as configured."""
        from radar_io.coordinates.reference_path import load_path
        from radar_io.service.extras import AirDataReader, DeviationProcessor
        from radar_io.sinks.worker import SinkWorker

        self.path = load_path(cfg.path) if cfg.path else None
        if self.path is not None:
            if self.path.frame == "runway" and self.site is None:
                raise ConfigError("a runway-frame reference path needs a site (--site)")
            self.acq.processors.append(DeviationProcessor(self.path))
        self.sinks: dict[str, SinkWorker] = {}
        if cfg.tlm_out or cfg.da_out:
            from radar_io.sinks.uplink import DASink, TelemetrySink
            from radar_io.encoding.tlm1 import TelemetryEncoder

            if cfg.tlm_out:
                enc = TelemetryEncoder(cycle_s=cfg.tlm_cycle_s or None)
                self.sinks["tlm"] = SinkWorker("tlm", TelemetrySink(cfg.tlm_out, enc))
            if cfg.da_out:
                self.sinks["da"] = SinkWorker("da", DASink(cfg.da_out))
            for w in self.sinks.values():
                self.acq.processors.append(w.submit)
        self.air: AirDataReader | None = None
        if cfg.can:
            interface, channel = cfg.can.split(":", 1)
            self.air = AirDataReader(interface, channel, self.latest_radar, cfg.can_bitrate)

    def latest_radar(self) -> dict[str, Any] | None:
        items = self.history.latest(1)
        return items[0][1] if items else None

    def close(self) -> None:
        for w in self.sinks.values():
            w.close()
        if self.air is not None:
            self.air.close()

    def path_polyline(self, step_m: float = 50.0) -> dict[str, Any] | None:
        """The reference path sampled every ``step_m`` in the radar frame (for drawing)."""
        import numpy as np

        if self.path is None:
            return None
        from radar_io.coordinates.transforms import runway_to_radar

        s = np.append(np.arange(0.0, self.path.length_m, step_m), self.path.length_m)
        x, y, h = self.path.position(s)
        if self.path.frame == "runway":
            x, y, h = runway_to_radar(x, y, h, self.site)
        return {"frame": self.path.frame, "length_m": float(self.path.length_m),
                "x_m": np.round(x, 2).tolist(), "y_m": np.round(y, 2).tolist(),
                "h_m": np.round(h, 2).tolist()}

    def recording_path(self, rec_id: str) -> Path:
        if not _ID.match(rec_id) or ".." in rec_id:
            raise HTTPException(400, f"invalid recording id {rec_id!r}")
        base = self.recorder.dir.resolve()
        p = (base / f"{rec_id}.rdrlog").resolve()
        if p.parent != base:
            raise HTTPException(400, "path outside the data directory refused")
        if not p.is_file():
            raise HTTPException(404, f"no recording {rec_id!r}")
        return p

    def status(self) -> dict[str, Any]:
        st = self.acq.status()
        st.update(self.hub.stats())
        st["recording"] = self.recorder.current
        st["auto_record"] = self.recorder.auto
        st["calibration"] = self.acq.calibration.id
        st["control_enabled"] = self.token is not None
        st["replay"] = self.replay.state() if self.replay is not None and st["mode"] == "replay" \
            else None
        st["site"] = self.site.name if self.site else None
        st["version"] = __version__
        st["instance"] = self.instance
        st["path"] = self.cfg.path
        st["uplink"] = {k: w.stats() for k, w in self.sinks.items()}
        st["airdata"] = self.air.stats() if self.air is not None else None
        return st


#: GIL switch interval: the reader thread and the event loop take turns every 0.5 ms
#: instead of Python's default 5 ms, which would otherwise show up as websocket latency
SWITCH_INTERVAL_S = 0.0005


def create_app(cfg: ServiceConfig) -> FastAPI:
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    svc = Service(cfg)

    @asynccontextmanager
    async def lifespan(app: FastAPI):  # type: ignore[no-untyped-def]
        from radar_io.service.alarms import status_loop

        svc.hub.attach(asyncio.get_running_loop())
        svc.acq.start()
        alarm_task = asyncio.create_task(status_loop(svc, svc.alarms))
        try:
            yield
        finally:
            alarm_task.cancel()
            svc.acq.stop()
            svc.recorder.close()
            svc.close()

    app = FastAPI(title="radar_io", version=__version__, lifespan=lifespan,
                  description="Live tracking-radar data, recordings, replay and calibration. "
                  "Units: metres and degrees; field names carry their unit.")
    app.state.service = svc

    def require_token(authorization: str | None = Header(None)) -> None:
        if svc.token is None:
            raise HTTPException(403, f"control is disabled: no token configured (set {TOKEN_ENV} "
                                "or token_file)")
        if not authorization or not authorization.startswith("Bearer "):
            raise HTTPException(401, "control needs 'Authorization: Bearer <token>'",
                                headers={"WWW-Authenticate": "Bearer"})
        if not secrets.compare_digest(authorization[7:].strip().encode(), svc.token.encode()):
            raise HTTPException(403, "wrong token")

    control = [Depends(require_token)]

    @app.exception_handler(RadarIOError)
    async def _radar_error(_req: Any, exc: RadarIOError) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=422)

    @app.get("/api/status", tags=["live"])
    def status() -> dict[str, Any]:
        """Source, link state, framer counters, rate, lamps, recording, websocket clients."""
        return svc.status()

    @app.get("/api/site", tags=["live"])
    def site() -> dict[str, Any] | None:
        """The radar site (WGS-84 position, runway frame), or null when none is configured."""
        return svc.site.to_dict() if svc.site else None

    @app.get("/api/path", tags=["live"])
    def path() -> dict[str, Any] | None:
        """The reference path in the radar frame, sampled every 50 m (null when none)."""
        return svc.path_polyline()

    @app.get("/api/airdata", tags=["live"])
    def airdata(since: int = Query(0, ge=0), limit: int = Query(2000, ge=1, le=10000)
                ) -> dict[str, Any]:
        """The aircraft's 8 Hz air data from CAN (SI units), with the radar ground range and
        height at arrival; ``samples`` after ``air_seq`` = since."""
        if svc.air is None:
            raise HTTPException(404, "no CAN air-data source configured (--can interface:channel)")
        return {"samples": svc.air.since(since, limit), **svc.air.stats()}

    @app.get("/api/track", tags=["live"])
    def track(since: int | None = Query(None, ge=0, description="return messages after this msg_seq"),
              limit: int = Query(1000, ge=1, le=20000)) -> dict[str, Any]:
        """Recent measurements (decode columns + msg_seq + t_ns), oldest first."""
        items = svc.history.since(since, limit) if since is not None else svc.history.latest(limit)
        return {"messages": [m for _, m, _ in items], "last_msg_seq": svc.history.last_seq,
                "first_msg_seq": svc.history.first_seq}

    @app.websocket("/ws/live")
    async def ws_live(ws: WebSocket, from_: int | None = Query(None, alias="from", ge=0),
                      max_hz: float | None = Query(None, gt=0, le=1000)) -> None:
        await ws.accept()
        client = svc.hub.register(ws, max_hz)
        sender = asyncio.create_task(client.run(svc.history, from_))
        try:
            while True:
                recv = asyncio.create_task(ws.receive())
                done, _ = await asyncio.wait({recv, sender}, return_when=asyncio.FIRST_COMPLETED)
                if sender in done:
                    recv.cancel()
                    break
                if recv.result().get("type") == "websocket.disconnect":
                    break
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            svc.hub.unregister(client)
            sender.cancel()

    @app.get("/api/recordings", tags=["recordings"])
    def recordings() -> list[dict[str, Any]]:
        """Recordings in the data directory, newest first."""
        out = []
        for p in sorted(svc.recorder.dir.glob("*.rdrlog"), reverse=True):
            st = p.stat()
            out.append({"id": p.stem, "size_bytes": st.st_size, "modified_unix_s": st.st_mtime,
                        "open": p.stem == svc.recorder.current,
                        "download": f"/api/recordings/{p.stem}"})
        return out

    @app.get("/api/recordings/{rec_id}", tags=["recordings"])
    def download(rec_id: str) -> FileResponse:
        """The .rdrlog file itself."""
        p = svc.recording_path(rec_id)
        return FileResponse(p, media_type="application/octet-stream", filename=p.name)

    @app.get("/api/sync-events", tags=["recordings"])
    def sync_events(recording: str | None = None, limit: int = Query(1000, ge=1, le=100000)
                    ) -> list[dict[str, Any]]:
        """Sync (camera shutter) events: SYNC 0→1 edges. Live (no ``recording``): as seen,
        with SEQ, TOD, receive time and the recording that holds them. For a recording: its
        edges decoded from the file, numbered by ``sync_index`` — the numbering
        POST /api/calibration/bias uses — with the radar's SR'/EL'/AZ' at each."""
        if recording is not None:
            from radar_io.calibration.sync_pairs import radar_at_sync_events

            events = radar_at_sync_events(svc.recording_path(recording), svc.spec)
            return [{**e, "recording": recording} for e in events][:limit]
        return [e.as_dict() for e in svc.recorder.sync_events[-limit:]]

    @app.post("/api/recordings/start", tags=["control"], dependencies=control)
    def rec_start() -> dict[str, Any]:
        if svc.acq.mode != "live":
            raise HTTPException(409, "cannot record while replaying")
        return {"recording": svc.recorder.start("manual")}

    @app.post("/api/recordings/stop", tags=["control"], dependencies=control)
    def rec_stop() -> dict[str, Any]:
        return {"closed": svc.recorder.stop()}

    @app.post("/api/replay", tags=["control"], dependencies=control)
    def replay_start(req: ReplayRequest) -> dict[str, Any]:
        """Replay a recording through the live pipeline (the port is released meanwhile)."""
        path = svc.recording_path(req.recording)
        if req.recording == svc.recorder.current:
            raise HTTPException(409, "that recording is still being written")
        try:
            ctl = ReplaySource(path, req.speed)
        except RadarIOError as exc:
            raise HTTPException(422, str(exc)) from exc
        svc.recorder.stop()
        svc.replay = ctl
        svc.acq.switch_source(ctl, "replay")
        return ctl.state()

    def _replay() -> ReplaySource:
        if svc.replay is None or svc.acq.mode != "replay":
            raise HTTPException(409, "no replay running")
        return svc.replay

    @app.get("/api/replay", tags=["replay"])
    def replay_state() -> dict[str, Any]:
        return _replay().state()

    @app.post("/api/replay/pause", tags=["control"], dependencies=control)
    def replay_pause() -> dict[str, Any]:
        r = _replay()
        r.pause()
        return r.state()

    @app.post("/api/replay/resume", tags=["control"], dependencies=control)
    def replay_resume() -> dict[str, Any]:
        r = _replay()
        r.resume()
        return r.state()

    @app.post("/api/replay/seek", tags=["control"], dependencies=control)
    def replay_seek(req: SeekRequest) -> dict[str, Any]:
        r = _replay()
        r.seek(req.position_s)
        return r.state()

    @app.post("/api/replay/step", tags=["control"], dependencies=control)
    def replay_step(req: StepRequest = Body(StepRequest())) -> dict[str, Any]:
        r = _replay()
        r.step(req.n)
        return r.state()

    @app.post("/api/replay/speed", tags=["control"], dependencies=control)
    def replay_speed(req: SpeedRequest) -> dict[str, Any]:
        r = _replay()
        r.set_speed(req.speed)
        return r.state()

    @app.post("/api/replay/stop", tags=["control"], dependencies=control)
    def replay_stop() -> dict[str, Any]:
        """Back to the live source."""
        _replay()
        from radar_io.sources import open_source

        svc.acq.switch_source(open_source(svc.cfg.source), "live")
        return {"mode": "live", "source": svc.cfg.source}

    @app.get("/api/calibration", tags=["calibration"])
    def get_calibration() -> dict[str, Any]:
        return svc.acq.calibration.to_dict()

    @app.put("/api/calibration", tags=["control"], dependencies=control)
    def put_calibration(doc: dict[str, Any] = Body(..., examples=[{
            "format": "radar_io-calibration/1", "id": "flight-7",
            "biases": {"dsr_m": 3.1, "del_deg": -0.012, "daz_deg": 0.034}}])) -> dict[str, Any]:
        """Apply a calibration set live (and keep it as the active set for restarts)."""
        try:
            cal = Calibration.from_dict(doc, source="request")
        except ConfigError as exc:
            raise HTTPException(422, str(exc)) from exc
        if not cal.created_utc:
            cal = Calibration(**{**cal.__dict__, "created_utc": utc_now_iso()})
        if not _ID.match(cal.id):
            raise HTTPException(422, f"calibration id {cal.id!r} must be a plain name")
        save_calibration(cal, svc.cal_dir / f"{cal.id}.json")
        save_calibration(cal, svc.cal_dir / "active.json")
        svc.acq.set_calibration(cal)
        return cal.to_dict()

    @app.post("/api/calibration/bias", tags=["control"], dependencies=control)
    def estimate_bias(req: BiasRequest) -> dict[str, Any]:
        """Pair photo positions with the radar's SR'/EL'/AZ' at the recorded sync events and
        estimate ΔSR/ΔEL/ΔAZ (calibration.md §8). Nothing is applied: review the proposed
        set, then PUT it to /api/calibration."""
        import numpy as np

        from radar_io.calibration.bias import bias_calibration, bias_statistics, photo_to_radar
        from radar_io.calibration.sync_pairs import radar_at_sync_events

        if not _ID.match(req.id):
            raise HTTPException(422, f"calibration id {req.id!r} must be a plain name")
        events: dict[str, list[dict[str, Any]]] = {}
        pairs = []
        for k, ob in enumerate(req.observations):
            if ob.recording not in events:
                events[ob.recording] = radar_at_sync_events(svc.recording_path(ob.recording),
                                                            svc.spec)
            evs = events[ob.recording]
            if ob.sync_index >= len(evs):
                raise HTTPException(422, f"observation {k}: recording {ob.recording} has "
                                    f"{len(evs)} sync events, no index {ob.sync_index}")
            ev = evs[ob.sync_index]
            if not ev["complete"]:
                raise HTTPException(422, f"observation {k}: sync event {ob.sync_index} of "
                                    f"{ob.recording} began before the recording")
            if not ev["rx_good"]:
                raise HTTPException(422, f"observation {k}: the radar was NG at sync event "
                                    f"{ob.sync_index} of {ob.recording}")
            if None not in (ob.photo_x_m, ob.photo_y_m, ob.photo_z_m):
                sr, el, az = (float(v) for v in photo_to_radar(
                    np.array([ob.photo_x_m]), np.array([ob.photo_y_m]), np.array([ob.photo_z_m])))
            elif None not in (ob.photo_sr_m, ob.photo_el_deg, ob.photo_az_deg):
                sr, el, az = ob.photo_sr_m, ob.photo_el_deg, ob.photo_az_deg
            else:
                raise HTTPException(422, f"observation {k}: give photo_x_m/y_m/z_m or "
                                    "photo_sr_m/el_deg/az_deg")
            pairs.append({"group": ob.group, "recording": ob.recording,
                          "sync_index": ob.sync_index, "seq": ev["seq"], "tod_s": ev["tod_s"],
                          "radar_sr_m": ev["sr_m"], "radar_el_deg": ev["el_deg"],
                          "radar_az_deg": ev["az_deg"], "photo_sr_m": sr, "photo_el_deg": el,
                          "photo_az_deg": az})
        stats = bias_statistics(
            [p["group"] for p in pairs],
            tuple(np.array([p[k] for p in pairs]) for k in ("photo_sr_m", "photo_el_deg",
                                                             "photo_az_deg")),
            tuple(np.array([p[k] for p in pairs]) for k in ("radar_sr_m", "radar_el_deg",
                                                             "radar_az_deg")))
        cal = bias_calibration(stats, cal_id=req.id, provenance={
            "method": "calibration.md §8 via POST /api/calibration/bias",
            "recordings": sorted(events), "pairs": len(pairs)})
        return {"pairs": pairs, "statistics": stats, "calibration": cal.to_dict()}

    from radar_io.service.routers.coordinates import router as coordinates_router
    from radar_io.service.routers.runway import router as runway_router

    from radar_io.service.routers.alarms import router as alarms_router
    from radar_io.service.routers.report import router as report_router

    app.include_router(runway_router)
    app.include_router(coordinates_router)
    app.include_router(alarms_router)
    app.include_router(report_router)
    app.mount("/static", StaticFiles(directory=WEB_DIR), name="static")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(WEB_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    return app

