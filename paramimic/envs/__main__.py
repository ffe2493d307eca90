"""python -m paramimic.envs: rewrite paramimic/gym_envs.json, the gymnasium ids `import paramimic`
registers, from the character registry."""

import json
from pathlib import Path

from paramimic.envs import registered_envs

out = Path(__file__).resolve().parent.parent / "gym_envs.json"
out.write_text(json.dumps(registered_envs(), indent=1, sort_keys=True) + "\n")
print(f"wrote {out}")
