"""How long `paramimic clip import` takes on a long recording: the shared CMU walk (8.3 s at 120
fps) repeated to `--minutes` of motion capture (the same skeleton, frames appended), imported
at 30 fps with the feet put on the floor. Target: a 10-minute file at 120 fps in under 10 s.
Run it alone on the machine.

    python benchmarks/bvh_import.py [--minutes 10]

Writes benchmarks/results/bvh_import/bvh_import.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

from paramimic.characters.bvh_import import import_bvh

ROOT = Path(__file__).resolve().parent.parent
SOURCE = ROOT.parent / "shared" / "motions" / "bvh" / "cmu_131_01_walk.bvh"
RESULTS = ROOT / "benchmarks" / "results" / "bvh_import"


def long_file(minutes: float, folder: Path) -> tuple[Path, int]:
    head, motion = SOURCE.read_text().split("MOTION")
    lines = motion.strip().splitlines()
    frame_time = float(lines[1].split(":")[1])
    rows = lines[2:]
    count = int(round(minutes * 60 / frame_time))
    body = [rows[i % len(rows)] for i in range(count)]
    path = folder / "long.bvh"
    path.write_text(f"{head}MOTION\nFrames: {count}\nFrame Time: {frame_time}\n" + "\n".join(body))
    return path, count


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=10.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path, frames = long_file(args.minutes, Path(tmp))
        t0 = time.perf_counter()
        imported = import_bvh(path)
        seconds = time.perf_counter() - t0
    out = {
        "minutes": args.minutes,
        "source_frames": frames,
        "source_fps": imported.report["source_fps"],
        "clip_frames": imported.report["frames"],
        "import_seconds": seconds,
        "target_seconds": 10.0,
        "met": seconds < 10.0,
        "machine": platform.processor() or platform.machine(),
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bvh_import.json").write_text(json.dumps(out, indent=2))
    print(f"{args.minutes:g} min at {out['source_fps']:g} fps ({frames:,} frames) imported in "
          f"{seconds:.1f} s (target < 10 s: {'met' if out['met'] else 'missed'})")  # fmt: skip


if __name__ == "__main__":
    main()
