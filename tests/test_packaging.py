"""The build stays supported (no setuptools deprecations: an SPDX license string and a
setuptools floor that knows it), and the constraints file pins what pyproject asks for."""

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("hook", ["wheel", "editable"])
def test_the_build_backend_warns_about_nothing(tmp_path, hook):
    code = (
        "from setuptools import build_meta;"
        f"print(build_meta.prepare_metadata_for_build_{hook}({str(tmp_path)!r}))"
    )
    res = subprocess.run([sys.executable, "-W", "error", "-c", code], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "deprecat" not in (res.stdout + res.stderr).lower()
    [metadata] = tmp_path.glob("*.dist-info/METADATA")
    text = metadata.read_text()
    assert "License-Expression: MIT" in text and "License-File: LICENSE" in text


def test_the_constraints_file_satisfies_pyproject():
    """constraints.txt (what make, CI and the image install from) pins every direct dependency
    inside pyproject's ranges."""
    from packaging.requirements import Requirement

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    wanted = [Requirement(r) for r in project["dependencies"]]
    for extra in ("test", "bench", "export"):
        wanted += [Requirement(r) for r in project["optional-dependencies"][extra]]
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_.\-]+)==([^\s;]+)", line)
        if m:
            pins[m.group(1).lower().replace("_", "-")] = m.group(2)
    for req in wanted:
        name = req.name.lower().replace("_", "-")
        assert name in pins, f"{req.name} is not pinned in constraints.txt (make lock)"
        assert req.specifier.contains(pins[name].split("+")[0], prereleases=True), (
            f"constraints.txt pins {name}=={pins[name]}, outside pyproject's {req}"
        )
