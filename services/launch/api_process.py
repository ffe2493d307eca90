"""The API as a child process of the launcher (`paramimic api`), stopped with it."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import httpx

from services.launch.processes import dying_with_parent, stop_process


class ApiProcess:
    def __init__(
        self, redis_url: str, host: str, port: int, token: str | None, log_path: Path
    ) -> None:
        self.redis_url, self.host, self.port, self.token = redis_url, host, port, token
        self.log_path = log_path
        self.process: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def start(self, timeout: float = 60.0) -> str:
        env = os.environ | {"REDIS_URL": self.redis_url}
        env.pop("PARAMIMIC_API_TOKEN", None)
        env.pop("RAY_AUTH_TOKEN", None)  # the API reads Redis only: it needs no Ray secret
        if self.token:
            env["PARAMIMIC_API_TOKEN"] = self.token  # not on the command line, where ps shows it
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                dying_with_parent(  # it dies with the launcher
                    [
                        sys.executable,
                        "-m",
                        "services.cli",
                        "api",
                        "--host",
                        self.host,
                        "--port",
                        str(self.port),
                    ]
                ),  # fmt: skip
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # Ctrl-C reaches the launcher, which stops this
            )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                break
            try:
                if httpx.get(f"{self.url}/health", timeout=1.0).status_code == 200:
                    return self.url
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        self.stop()
        tail = self.log_path.read_text(errors="replace")[-2000:]
        raise RuntimeError(f"the API did not start on {self.url}:\n{tail}")

    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def stop(self, timeout: float = 10.0) -> None:
        stop_process(self.process, timeout)
        self.process = None
