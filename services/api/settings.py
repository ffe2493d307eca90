"""API settings, from the environment (never from a .env file in the working directory: it
could turn the write endpoints on unnoticed)."""

from __future__ import annotations

from pydantic import AliasChoices, Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(extra="ignore")

    redis_url: str = Field(
        "redis://127.0.0.1:6379/0",
        validation_alias=AliasChoices("REDIS_URL", "redis_url"),
        description="the Redis that holds the runs' state",
    )
    api_token: SecretStr | None = Field(
        None,
        validation_alias=AliasChoices("PARAMIMIC_API_TOKEN", "api_token"),
        description="bearer token for the endpoints that change a run; none: they are disabled",
    )
    allowed_hosts: list[str] = Field(
        ["127.0.0.1", "localhost", "::1"],
        validation_alias=AliasChoices("PARAMIMIC_ALLOWED_HOSTS", "allowed_hosts"),
        description="Host headers the API answers (a JSON list); others get 400 (DNS "
        "rebinding). Behind a proxy or on a LAN name add yours, e.g. "
        '\'["paramimic.lan", "127.0.0.1"]\'',
    )
