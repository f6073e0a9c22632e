"""Annotations (test points, notes, markers): ``POST /api/annotations`` (operator) and
``GET /api/annotations``.

An annotation goes to the events of the recording open at its time (``<id>.events.jsonl``,
through the recorder's writer: append-only, fsynced, never written on the request's
thread) and, always, to the service's annotations log (``DATA_DIR/annotations.jsonl``,
its own writer thread), so one made with no recording open is kept too (``recording``
null; ``radar-io annotate REC`` attaches it to a recording afterwards).
"""

from __future__ import annotations

import secrets
import time
from typing import Any, Literal

from fastapi import APIRouter, Depends, Query
from pydantic import BaseModel, Field

from radar_io.service.auth import Principal
from radar_io.service.errors import responses
from radar_io.service.routers.deps import OPERATOR_DEP, get_state
from radar_io.service.state import ID_PATTERN, ServiceState

router = APIRouter(tags=["annotations"])

ANNOTATION_KINDS = ("note", "test_point_start", "test_point_end", "marker")


class AnnotationIn(BaseModel):
    kind: Literal["note", "test_point_start", "test_point_end", "marker"] = "marker"
    label: str = Field("", max_length=200, description="e.g. TP4")
    text: str = Field("", max_length=4000)
    t_ns: int | None = Field(None, ge=0, le=(1 << 63) - 1,
                             description="wall-clock time, ns since the epoch (default: now)")


def annotation_event(kind: str, label: str, text: str, actor: str | None,
                     aid: str | None = None) -> dict[str, Any]:
    """The fields of an ``annotation`` event (``t_ns``/``mono_ns`` are added by the writer)."""
    return {"annotation_kind": kind, "label": label, "text": text,
            "id": aid or secrets.token_hex(8), "actor": actor}


@router.post("/api/annotations", tags=["control"], status_code=201,
             responses=responses(401, 403, 422))
async def annotate(body: AnnotationIn, who: Principal = Depends(OPERATOR_DEP),
                   state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Add an annotation (operator): ``{"id", "t_ns", "recording"}`` — the recording open
    at ``t_ns`` (or closed since the service started and spanning it), or null: it is kept
    in the service's annotations log either way."""
    t_ns = time.time_ns() if body.t_ns is None else body.t_ns
    fields = annotation_event(body.kind, body.label, body.text, who.actor)
    rec = state.recorder.annotate(fields, t_ns)
    state.annotations.append({"kind": "annotation", "t_ns": t_ns, **fields, "recording": rec})
    return {"id": fields["id"], "t_ns": t_ns, "recording": rec}


@router.get("/api/annotations", responses=responses(404, 422))
def list_annotations(recording: str | None = Query(None, pattern=ID_PATTERN,
                                              description="recording id; none = all"),
                state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Annotations, oldest first: ``{"annotations": [{id, kind, label, text, t_ns, actor,
    recording}]}``. With ``recording``: those in its events file (made live or with
    ``radar-io annotate``) and those the service holds for it; without: all the service
    holds."""
    from radar_io.sinks.ch10 import read_events_file

    state.annotations.flush(2.0)
    held = [r for r in state.annotations.read() if recording is None
            or r.get("recording") == recording]
    if recording is not None:
        path = state.recording_path(recording)
        held += [{**e, "recording": recording}
                 for e in read_events_file(path.with_suffix(".events.jsonl"))
                 if e.get("kind") == "annotation"]
    out: dict[str, dict[str, Any]] = {}
    for r in held:
        out.setdefault(str(r.get("id")), {
            "id": r.get("id"), "kind": r.get("annotation_kind"), "label": r.get("label", ""),
            "text": r.get("text", ""), "t_ns": r.get("t_ns"), "actor": r.get("actor"),
            "recording": r.get("recording")})
    return {"annotations": sorted(out.values(), key=lambda a: int(a["t_ns"] or 0))}
