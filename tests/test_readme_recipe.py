"""The multi-machine recipe of docs/training.md, run for real: the Redis config it writes holds the
password in a file only its owner reads, and the Redis it starts answers on loopback only."""

from __future__ import annotations

import re
import socket
import subprocess
from pathlib import Path

import psutil
import pytest
import redis
from conftest import wait_until

from services.launch.processes import free_port, stop_process
from services.launch.redis_server import redis_server_binary

ROOT = Path(__file__).resolve().parent.parent


def _recipe() -> list[str]:
    """The head machine's block of "More machines without containers"."""
    text = (ROOT / "docs" / "training.md").read_text()
    section = text.split("## More machines without containers", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return block.replace("\\\n", " ").splitlines()


def _outside_ip() -> str | None:
    """An address of this machine that is not loopback, if it has one."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("192.0.2.1", 9))  # TEST-NET: nothing is sent
            ip = s.getsockname()[0]
        except OSError:
            return None
    return None if ip.startswith("127.") else ip


def test_the_recipes_redis_keeps_its_password_and_loopback(tmp_path):
    lines = _recipe()
    password = next(x for x in lines if x.startswith("export REDIS_PASSWORD="))
    write = next(x for x in lines if "> redis.conf" in x)
    script = "\n".join([password.replace("python", "python3"), write, 'echo "$REDIS_PASSWORD"'])
    done = subprocess.run(["bash", "-c", script], cwd=tmp_path, umask=0o022,
                          capture_output=True, text=True, check=True)  # fmt: skip
    secret = done.stdout.strip()
    conf = tmp_path / "redis.conf"
    assert conf.stat().st_mode & 0o777 == 0o600  # a umask of 022 around it
    text = conf.read_text()
    assert f'requirepass "{secret}"' in text and len(secret) >= 24
    assert re.search(r"^bind 127\.0\.0\.1$", text, re.M)
    port = free_port()
    conf.write_text(re.sub(r"^port \d+$", f"port {port}", text, flags=re.M) + f"dir {tmp_path}\n")
    server = subprocess.Popen([redis_server_binary(), str(conf)], cwd=tmp_path,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        client = redis.Redis(port=port, password=secret, socket_connect_timeout=1)

        def up() -> bool:
            try:
                return client.ping()
            except redis.ConnectionError:
                return False

        wait_until(up, 30, "the recipe's Redis")
        with pytest.raises(redis.AuthenticationError):
            redis.Redis(port=port, password="wrong").ping()
        # the server listens on loopback only (its own sockets, seen by the kernel) ...
        listening = {c.laddr.ip for c in psutil.Process(server.pid).net_connections("inet")
                     if c.status == psutil.CONN_LISTEN}  # fmt: skip
        assert listening and listening <= {"127.0.0.1", "::1"}, listening
        # ... and an address of this machine that is not loopback, where it has one, is refused
        outside = _outside_ip()
        if outside is not None:
            with pytest.raises(OSError), socket.create_connection((outside, port), timeout=2):
                pass
    finally:
        stop_process(server)
