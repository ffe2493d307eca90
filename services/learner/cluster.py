"""Joining a Ray cluster, or starting a local one bound to loopback."""

from __future__ import annotations

import os
import secrets

import ray


def connect(address: str | None, node_ip: str | None = None) -> bool:
    """Join `address` (or $RAY_ADDRESS) as the Ray node of this machine at `node_ip` (needed
    only when the machine has several addresses); else start a private local Ray of this run's
    own (`address="local"`: never the cluster that Ray's world-writable temp dir names in
    `ray_current_cluster`, nor a user's `ray start --head`). Returns True if started here."""
    address = address or os.environ.get("RAY_ADDRESS")
    if ray.is_initialized():
        return False
    if address:
        ray.init(address=address, log_to_driver=False, _node_ip_address=node_ip)
        return False
    start_private()
    return True


def start_private(**options) -> None:
    """A new local Ray for this process alone: token authentication, no dashboard, and never
    an existing cluster (Ray would join the one its temp dir names)."""
    local_token_auth()
    options = {"include_dashboard": False, "log_to_driver": False} | options
    ray.init(address="local", _node_ip_address="127.0.0.1", **options)


def local_token_auth() -> None:
    """A local Ray that only its own processes can use: token authentication (Ray >= 2.52) with
    a fresh random token per launch, passed in the environment (inherited by the GCS, raylet and
    workers; other users can't read it, `ps` does not show it) rather than ~/.ray/auth_token.
    A token the user already set (RAY_AUTH_TOKEN / RAY_AUTH_TOKEN_PATH) is kept."""
    from ray._private.authentication.authentication_token_setup import _enable_token_auth

    if not (os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH")):
        os.environ["RAY_AUTH_TOKEN"] = secrets.token_hex(32)
    _enable_token_auth()  # sets RAY_AUTH_MODE=token and refreshes Ray's cached config
