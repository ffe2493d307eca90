"""The progress API: an app factory over Redis (FastAPI + uvicorn)."""

from __future__ import annotations

import json
from contextlib import asynccontextmanager

import redis.asyncio as aioredis
import uvicorn
from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError, ResponseValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from redis.exceptions import ConnectionError as RedisConnectionError
from redis.exceptions import TimeoutError as RedisTimeoutError
from starlette.middleware.trustedhost import TrustedHostMiddleware

from services.api import dashboard
from services.api.routes import EliteCache, router
from services.api.settings import Settings
from services.asgi import BodyLimit
from services.store import finite

MAX_BODY = 4096  # bytes: the largest mutating request (PUT k) is ~20
RETRY_AFTER = "5"  # seconds, on 503


async def redis_unavailable(request: Request, exc: Exception) -> JSONResponse:
    """503 with Retry-After; the message names no internal host or port."""
    return JSONResponse(
        {"detail": f"the run store (Redis) is unavailable ({type(exc).__name__}); retry later"},
        status_code=503,
        headers={"Retry-After": RETRY_AFTER},
    )


async def damaged_state(request: Request, exc: Exception) -> JSONResponse:
    """Stored JSON that does not parse or lacks what it should hold: a clear answer, not a 500."""
    return JSONResponse(
        {
            "detail": f"the stored state behind {request.url.path} is damaged and cannot be read "
            f"({type(exc).__name__}: {str(exc)[:200]})"
        },  # fmt: skip
        status_code=409,
    )


async def invalid_request(request: Request, exc: RequestValidationError) -> JSONResponse:
    """422 with the errors; a NaN or Infinity the body held is echoed as null (JSON has no
    NaN: FastAPI's own handler fails to encode it and answers 500)."""
    return JSONResponse(status_code=422, content={"detail": finite(jsonable_encoder(exc.errors()))})


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        app.state.redis = aioredis.from_url(
            settings.redis_url, decode_responses=True, socket_timeout=5, socket_connect_timeout=2
        )
        yield
        await app.state.redis.aclose()

    app = FastAPI(
        title="paramimic",
        summary="Progress and curriculum state of paramimic training runs",
        lifespan=lifespan,
        # no Swagger UI or ReDoc: they load scripts from a CDN into the origin that holds the
        # dashboard's token; the schema stays at /openapi.json
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.elite_cache = EliteCache()
    app.add_exception_handler(RequestValidationError, invalid_request)
    app.include_router(router)
    app.include_router(dashboard.router)
    for error in (RedisConnectionError, RedisTimeoutError):
        app.add_exception_handler(error, redis_unavailable)
    damaged = (json.JSONDecodeError, KeyError, TypeError, ValidationError, ResponseValidationError)
    for error in damaged:
        app.add_exception_handler(error, damaged_state)
    app.add_middleware(BodyLimit, limit=MAX_BODY)
    # a Host header not ours (DNS rebinding: a page of another site resolving its own name to
    # 127.0.0.1) is refused before any route runs
    app.add_middleware(TrustedHostMiddleware, allowed_hosts=settings.allowed_hosts)
    return app


def serve(settings: Settings, host: str = "127.0.0.1", port: int = 8000) -> None:
    uvicorn.run(create_app(settings), host=host, port=port, log_level="warning")
