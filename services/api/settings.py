"""API settings, from the environment (or a .env file)."""

from __future__ import annotations

from pydantic import AliasChoices, Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_file=".env", extra="ignore")

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
