"""The progress API: an app factory over Redis (FastAPI + uvicorn)."""

from __future__ import annotations

from contextlib import asynccontextmanager

import redis.asyncio as aioredis
import uvicorn
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from redis.exceptions import ConnectionError as RedisConnectionError
from redis.exceptions import TimeoutError as RedisTimeoutError

from services.api.routes import router
from services.api.settings import Settings


async def redis_unavailable(request: Request, exc: Exception) -> JSONResponse:
    return JSONResponse({"detail": f"Redis is unavailable: {exc}"}, status_code=503)


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
    )
    app.state.settings = settings
    app.include_router(router)
    for error in (RedisConnectionError, RedisTimeoutError):
        app.add_exception_handler(error, redis_unavailable)
    return app


def serve(settings: Settings, host: str = "127.0.0.1", port: int = 8000) -> None:
    uvicorn.run(create_app(settings), host=host, port=port, log_level="warning")
