"""Coordinate conversions over HTTP (radar-interface.md §5), so that clients such as the
dashboard never copy the formulas: runway frame → radar rectangular frame with the
service's configured site. Pure computation, no state change, so no token is needed.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field, model_validator

from radar_io.service.errors import responses

MAX_POINTS = 10_000  #: points accepted in one request (3 columns fit the 1 MiB body limit)

router = APIRouter(tags=["coordinates"])

Column = Annotated[list[float], Field(min_length=1, max_length=MAX_POINTS)]


class RunwayPoints(BaseModel):
    """Points in the runway frame: X_r along the approach heading, Y_r right, H_r up [m]."""

    xr_m: Column = Field(description="along the runway heading from the runway origin, m")
    yr_m: Column = Field(description="right of the runway centre line, m")
    hr_m: Column = Field(description="up from the runway origin, m")

    @model_validator(mode="after")
    def _same_length(self) -> RunwayPoints:
        n = {len(self.xr_m), len(self.yr_m), len(self.hr_m)}
        if len(n) != 1:
            raise ValueError(f"xr_m, yr_m and hr_m must have the same length, got "
                             f"{len(self.xr_m)}, {len(self.yr_m)}, {len(self.hr_m)}")
        return self


@router.post("/api/coordinates/runway-to-radar", responses=responses(404))
def runway_to_radar(req: RunwayPoints, request: Request) -> dict[str, Any]:
    """Radar rectangular X (north), Y (east), H (up) [m] of runway-frame points, eqs. (2-9)…
    (2-11) inverted, with the configured site's runway heading and radar position."""
    import numpy as np

    from radar_io.coordinates import transforms
    from radar_io.errors import NotFoundError, ValidationError

    site = request.app.state.service.site
    if site is None:
        raise NotFoundError("no radar site configured (serve --site SITE.toml)")
    cols = {k: np.asarray(getattr(req, k), dtype=float) for k in ("xr_m", "yr_m", "hr_m")}
    for k, v in cols.items():  # checked here: a 422 echoing NaN in its body is not JSON
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise ValidationError(f"{k}[{bad[0]}] is not a finite number")
    x, y, h = transforms.runway_to_radar(cols["xr_m"], cols["yr_m"], cols["hr_m"], site)
    return {"site": site.name, "x_m": x.tolist(), "y_m": y.tolist(), "h_m": h.tolist()}
