"""The dashboard the API serves at `/`: a runs page and a live page per run (services/api/static/),
drawn in the browser with plotly.js from the `plotly` wheel (served at /static/plotly.min.js: no
CDN, no Node build, works offline). The pages call only the API's own JSON endpoints, every 2 s,
and send pause / resume / k with the bearer token the user types in."""

from __future__ import annotations

from functools import cache
from pathlib import Path as FilePath

from fastapi import APIRouter, HTTPException, Path, status
from fastapi.responses import FileResponse, Response

from services.keys import RUN_ID

STATIC = FilePath(__file__).resolve().parent / "static"
ASSETS = {"dashboard.css": "text/css", "common.js": "text/javascript", "runs.js":
          "text/javascript", "run.js": "text/javascript"}  # fmt: skip

router = APIRouter(include_in_schema=False)


@cache
def plotly_js() -> bytes:
    from plotly.offline import get_plotlyjs

    return get_plotlyjs().encode()


@router.get("/static/plotly.min.js")
def plotly_bundle() -> Response:
    return Response(
        plotly_js(),
        media_type="text/javascript",
        headers={"Cache-Control": "public, max-age=86400"},
    )


@router.get("/static/{name}")
def asset(name: str) -> FileResponse:
    if name not in ASSETS:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no asset {name!r}")
    return FileResponse(STATIC / name, media_type=ASSETS[name])


@router.get("/")
def runs_page() -> FileResponse:
    return FileResponse(STATIC / "runs.html", media_type="text/html")


@router.get("/ui/runs/{run}")
def run_page(run: str = Path(pattern=RUN_ID.pattern)) -> FileResponse:
    return FileResponse(STATIC / "run.html", media_type="text/html")
