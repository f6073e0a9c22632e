"""One error body everywhere, and radar_io errors mapped to HTTP by class.

Every error answer has the shape of FastAPI's 422:
``{"detail": [{"loc": [...], "msg": "...", "type": "..."}]}``. A
:class:`~radar_io.errors.RadarIOError` raised by a route is answered by its branch:
ValidationError 422, NotFoundError 404, ConflictError 409, StorageError 507,
UnavailableError 503 (anything else 500).
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel
from starlette.exceptions import HTTPException as StarletteHTTPException

from radar_io.errors import (
    ConflictError,
    NotFoundError,
    RadarIOError,
    StorageError,
    UnavailableError,
    ValidationError,
)

#: radar_io error class → (HTTP status, error type), first match wins
STATUS_BY_CLASS: tuple[tuple[type[RadarIOError], int, str], ...] = (
    (ValidationError, 422, "validation_error"),
    (NotFoundError, 404, "not_found"),
    (ConflictError, 409, "conflict"),
    (StorageError, 507, "insufficient_storage"),
    (UnavailableError, 503, "unavailable"),
)

_TYPE_BY_STATUS = {400: "bad_request", 401: "unauthorized", 403: "forbidden", 404: "not_found",
                   405: "method_not_allowed", 409: "conflict", 410: "gone", 413: "payload_too_large",
                   421: "host_not_allowed", 422: "validation_error", 429: "too_many_requests",
                   431: "request_header_fields_too_large", 503: "unavailable",
                   507: "insufficient_storage"}


class ErrorItem(BaseModel):
    loc: list[str | int]
    msg: str
    type: str


class ErrorBody(BaseModel):
    """Every error answer: a list of reasons (as FastAPI's 422)."""

    detail: list[ErrorItem]


def error_body(status: int, msg: str, loc: list[str | int] | None = None,
               type_: str | None = None) -> dict[str, Any]:
    return {"detail": [{"loc": loc or [], "msg": msg,
                        "type": type_ or _TYPE_BY_STATUS.get(status, "error")}]}


def error_response(status: int, msg: str, headers: dict[str, str] | None = None,
                   type_: str | None = None) -> JSONResponse:
    return JSONResponse(error_body(status, msg, type_=type_), status_code=status, headers=headers)


def status_of(exc: RadarIOError) -> tuple[int, str]:
    for cls, status, kind in STATUS_BY_CLASS:
        if isinstance(exc, cls):
            return status, kind
    return 500, "internal_error"


def _as_items(detail: Any, status: int) -> list[dict[str, Any]]:
    if isinstance(detail, list) and all(isinstance(d, dict) and "msg" in d for d in detail):
        return [{"loc": list(d.get("loc", [])), "msg": str(d["msg"]),
                 "type": str(d.get("type", _TYPE_BY_STATUS.get(status, "error")))} for d in detail]
    return error_body(status, str(detail))["detail"]


def install_error_handlers(app: FastAPI) -> None:
    """RadarIOError by class, HTTPException and request validation: one body shape."""

    @app.exception_handler(RadarIOError)
    async def _radar_error(_req: Request, exc: RadarIOError) -> JSONResponse:
        status, kind = status_of(exc)
        return error_response(status, str(exc), type_=kind)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(_req: Request, exc: StarletteHTTPException) -> JSONResponse:
        return JSONResponse({"detail": _as_items(exc.detail, exc.status_code)},
                            status_code=exc.status_code, headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def _validation(_req: Request, exc: RequestValidationError) -> JSONResponse:
        items = [{"loc": list(e.get("loc", [])), "msg": str(e.get("msg", "")),
                  "type": str(e.get("type", "value_error"))} for e in exc.errors()]
        return JSONResponse({"detail": items}, status_code=422)


def responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses=`` for the given error statuses, all with :class:`ErrorBody`."""
    text = {401: "no token given", 403: "control disabled, wrong token or foreign Origin",
            404: "not found", 409: "conflicts with the current state",
            410: "gone: the route was replaced (the message names its successor)",
            413: "request body too large", 421: "Host not allowed (allowed_hosts)",
            422: "invalid request",
            429: "too many clients, jobs or expensive requests at once (Retry-After)",
            431: "request headers too large",
            503: "a device or link is not available", 507: "no space left for the recording"}
    return {c: {"model": ErrorBody, "description": text.get(c, "error")} for c in codes}
