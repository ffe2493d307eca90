"""Joining a Ray cluster, or starting a local one bound to loopback."""

from __future__ import annotations

import os

import ray


def connect(address: str | None, node_ip: str | None = None) -> bool:
    """Join `address` (or $RAY_ADDRESS) as the Ray node of this machine at `node_ip` (needed
    only when the machine has several addresses); else start a local Ray. Returns True if
    started here."""
    address = address or os.environ.get("RAY_ADDRESS")
    if ray.is_initialized():
        return False
    if address:
        ray.init(address=address, log_to_driver=False, _node_ip_address=node_ip)
        return False
    ray.init(include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
    return True
