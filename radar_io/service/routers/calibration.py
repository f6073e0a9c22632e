"""Calibration: the active set (get, put live), and the bias estimate from photo
observations at recorded sync events (calibration.md §8)."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Body, Depends
from pydantic import BaseModel, ConfigDict, Field

from radar_io.decoding.biases import BIAS_LIMITS, FORMAT, Calibration, utc_now_iso
from radar_io.service.errors import responses
from radar_io.service.routers.deps import ADMIN, get_state
from radar_io.service.state import ID_PATTERN, ServiceState, check_id

router = APIRouter(tags=["calibration"])


class PhotoObservation(BaseModel):
    """A photo position (from resection) at a sync event of a recording."""

    group: str = Field(description="flight / group name for the per-group statistics")
    recording: str = Field(pattern=ID_PATTERN, description="recording id holding the sync event")
    sync_index: int = Field(ge=0, description="0-based index of the SYNC 0→1 edge in the recording")
    photo_x_m: float | None = Field(None, description="north of the radar (ground frame)")
    photo_y_m: float | None = Field(None, description="east of the radar")
    photo_z_m: float | None = Field(None, description="down (Z = −H)")
    photo_sr_m: float | None = None
    photo_el_deg: float | None = None
    photo_az_deg: float | None = None


class Biases(BaseModel):
    """ΔSR, ΔEL, ΔAZ added after servo-lag compensation."""

    model_config = ConfigDict(extra="forbid")
    dsr_m: float = Field(0.0, ge=-BIAS_LIMITS["dsr_m"], le=BIAS_LIMITS["dsr_m"],
                         description="slant-range bias, m")
    del_deg: float = Field(0.0, ge=-BIAS_LIMITS["del_deg"], le=BIAS_LIMITS["del_deg"],
                           description="elevation bias, deg")
    daz_deg: float = Field(0.0, ge=-BIAS_LIMITS["daz_deg"], le=BIAS_LIMITS["daz_deg"],
                           description="azimuth bias, deg")


class CalibrationDoc(BaseModel):
    """A calibration set (the document GET returns and POST /api/calibration/bias proposes)."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["radar_io-calibration/1"] = FORMAT
    id: str = Field("unnamed", pattern=ID_PATTERN, description="a plain name")
    biases: Biases
    created_utc: str = Field("", description="ISO-8601 UTC; set on PUT when empty")
    statistics: dict[str, Any] = Field(default_factory=dict)
    provenance: dict[str, Any] = Field(default_factory=dict)


class BiasRequest(BaseModel):
    id: str = Field(pattern=ID_PATTERN, description="id of the calibration set to propose")
    observations: list[PhotoObservation] = Field(min_length=1)


@router.get("/api/calibration")
def get_calibration(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """The calibration set applied now."""
    return state.live.calibration.to_dict()


@router.put("/api/calibration", tags=["control"], dependencies=ADMIN,
            responses=responses(401, 403, 422, 507))
def put_calibration(doc: CalibrationDoc = Body(..., examples=[{
        "format": "radar_io-calibration/1", "id": "flight-7",
        "biases": {"dsr_m": 3.1, "del_deg": -0.012, "daz_deg": 0.034}}]),
        state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Apply a calibration set live and keep it as the active set for restarts (written
    durably; every applied version is kept in ``calibrations/history/``)."""
    cal = Calibration.from_dict(doc.model_dump(), source="request")  # ConfigError → 422
    if not cal.created_utc:
        cal = Calibration(**{**cal.__dict__, "created_utc": utc_now_iso()})
    check_id(cal.id, "calibration id")
    state.calibrations.save(cal, apply=state.live.set_calibration)
    return cal.to_dict()


@router.post("/api/calibration/bias", tags=["control"], dependencies=ADMIN,
             responses=responses(401, 403, 404, 422))
def estimate_bias(req: BiasRequest, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Pair photo positions with the radar's SR'/EL'/AZ' at the recorded sync events and
    estimate ΔSR/ΔEL/ΔAZ (calibration.md §8). Nothing is applied: review the proposed
    set, then PUT it to /api/calibration."""
    from radar_io.calibration.pairing import estimate_bias as estimate
    from radar_io.calibration.sync_pairs import radar_at_sync_events

    check_id(req.id, "calibration id")
    events = {rec: radar_at_sync_events(state.recording_path(rec), state.spec)
              for rec in dict.fromkeys(ob.recording for ob in req.observations)}
    return estimate([ob.model_dump() for ob in req.observations], events, req.id,
                    method="calibration.md §8 via POST /api/calibration/bias")
