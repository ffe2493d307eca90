"""Checkpoints on disk: plain data only, written atomically, read without running code.

A checkpoint holds tensors, numbers, strings, lists, tuples and dicts; numpy arrays are stored as
tensors (`{"__ndarray__": tensor}`) or, for dtypes torch lacks, as lists with their dtype, and
come back as numpy arrays. Files are read with `torch.load(weights_only=True)`, which refuses any
pickled object that would construct arbitrary classes or call functions, so a planted file cannot
run code. Writes go to a temp file that is fsynced, renamed, and the directory fsynced;
`latest.pt` is a hard link to the newest `ckpt_<iteration>.pt`. A checkpoint whose float tensors
are not all finite is refused (`NonFiniteState`): a bad update never replaces a good file.

Checkpoints prove themselves: beside each file a manifest (`<file>.sha256`: the SHA-256 of its
bytes and its size) is written after the file's fsync, and reading a file checks it, and checks
every float in it (tensors, arrays and plain numbers) for finiteness; a run's latest that fails
either falls back to the newest ckpt_*.pt that passes both. A file written before manifests
existed loads with a warning.
"""

from __future__ import annotations

import hashlib
import math
import os
import pickle
import tempfile
import warnings
import zipfile
from importlib import resources
from pathlib import Path

import numpy as np
import torch

LATEST = "latest.pt"
WEIGHTS = ("learner", "marginal", "motion_net")  # the parts that must be finite
SUFFIX = ".pt"
TMP_PREFIX = ".tmp-"
_TORCH_DTYPES = {np.dtype(t) for t in ("bool", "uint8", "int8", "int16", "int32", "int64",
                                       "float16", "float32", "float64")}  # fmt: skip


class CheckpointError(RuntimeError):
    """A checkpoint file that cannot (or must not) be read."""


class NonFiniteState(ValueError):
    """A state with NaN or infinite weights; it is not written."""


def checkpoint_dir(run_dir: Path) -> Path:
    return Path(run_dir) / "checkpoints"


def encode(value):
    """The state as plain data that `weights_only` loading accepts (numpy -> tensors/lists)."""
    if isinstance(value, dict):
        return {k: encode(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(encode(v) for v in value)
    if isinstance(value, np.ndarray):
        if value.dtype in _TORCH_DTYPES:
            return {"__ndarray__": torch.from_numpy(np.ascontiguousarray(value).copy())}
        return {"__ndarray__": value.tolist(), "dtype": value.dtype.str}
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, bool | int | float | str | torch.Tensor):
        return value
    raise TypeError(f"a checkpoint holds plain data only, not {type(value).__name__}")


def decode(value):
    if isinstance(value, dict):
        if "__ndarray__" in value:
            data = value["__ndarray__"]
            if isinstance(data, torch.Tensor):
                return data.numpy()
            return np.asarray(data, dtype=np.dtype(value["dtype"]))
        return {k: decode(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(decode(v) for v in value)
    return value


def non_finite(value, where: str = "") -> str | None:
    """The path of the first float tensor/array/number in `value` that is not finite, or None."""
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list | tuple):
        items = enumerate(value)
    else:
        if isinstance(value, torch.Tensor) and value.is_floating_point():
            return None if bool(torch.isfinite(value).all()) else where
        if isinstance(value, np.ndarray) and value.dtype.kind == "f":
            return None if bool(np.isfinite(value).all()) else where
        if isinstance(value, float | np.floating):
            return None if math.isfinite(value) else where
        return None
    for k, v in items:
        bad = non_finite(v, f"{where}/{k}")
        if bad is not None:
            return bad
    return None


def save(run_dir: Path, state: dict, iteration: int, keep: int | None = None) -> Path:
    """Write ckpt_<iteration>.pt and point latest.pt at the same bytes; both atomically.

    The networks' weights must be finite (`NonFiniteState` otherwise, nothing written); `keep`
    prunes all but the newest `keep` ckpt files; stale temp files of crashed writers go.
    """
    bad = non_finite({k: state.get(k) for k in WEIGHTS})
    if bad is not None:
        raise NonFiniteState(f"not writing checkpoint {iteration}: non-finite values at {bad}")
    d = checkpoint_dir(run_dir)
    d.mkdir(parents=True, exist_ok=True)
    for stale in d.glob(f"{TMP_PREFIX}*"):  # a run has one writer (the run lock)
        stale.unlink(missing_ok=True)
    path = d / f"ckpt_{iteration:06d}.pt"
    fd, tmp = tempfile.mkstemp(dir=d, prefix=TMP_PREFIX, suffix=".pt")
    placed = False
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(encode(state), f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        placed = True
        _write_manifest(path)
        latest_tmp = d / f"{TMP_PREFIX}latest-{os.getpid()}"
        latest_tmp.unlink(missing_ok=True)
        os.link(path, latest_tmp)
        os.replace(latest_tmp, d / LATEST)
        _write_manifest(d / LATEST)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        if placed and not _manifest(path).is_file():  # no file without its manifest (full disk)
            path.unlink(missing_ok=True)
        raise
    _fsync_dir(d)
    if keep is not None:  # by iteration number (names sort as strings past 999,999)
        for old in sorted(d.glob("ckpt_*.pt"), key=_iteration)[:-keep]:
            old.unlink(missing_ok=True)
            _manifest(old).unlink(missing_ok=True)
    return path


def _iteration(path: Path) -> int:
    try:
        return int(path.stem.split("_", 1)[1])
    except (IndexError, ValueError):
        return -1


MANIFEST = ".sha256"


def _manifest(path: Path) -> Path:
    return path.with_name(path.name + MANIFEST)


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _write_manifest(path: Path) -> None:
    """`<file>.sha256`: the digest and size of `path`, written atomically after its fsync."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=TMP_PREFIX, suffix=MANIFEST)
    with os.fdopen(fd, "w") as f:
        f.write(f"{_digest(path)} {path.stat().st_size}\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, _manifest(path))


def verify(file: Path) -> bool:
    """Whether `file` matches its manifest (False: it has none, a file of an older release);
    CheckpointError if it does not match."""
    manifest = _manifest(file)
    if not manifest.is_file():
        return False
    try:
        digest, size = manifest.read_text().split()
    except (OSError, ValueError) as e:
        raise CheckpointError(f"{file}: its manifest {manifest.name} is unreadable: {e}") from None
    if file.stat().st_size != int(size) or _digest(file) != digest:
        raise CheckpointError(f"{file} does not match its manifest (damaged after it was written)")
    return True


def _fsync_dir(d: Path) -> None:
    fd = os.open(d, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def resolve(path: Path | str) -> Path:
    """A checkpoint file, a run directory / checkpoint directory holding latest.pt, or the name
    of a shipped controller (a path that exists wins)."""
    path = Path(path)
    if path.is_file():
        return path
    for candidate in (checkpoint_dir(path) / LATEST, path / LATEST):
        if candidate.is_file():
            return candidate
    named = None if path.exists() else shipped(str(path))
    if named is not None:
        return named
    raise FileNotFoundError(
        f"no checkpoint at {path} (looked for {checkpoint_dir(path) / LATEST}; shipped "
        f"controllers: {', '.join(shipped_names()) or 'none'})"
    )


def shipped_dir() -> Path:
    """Where the shipped controllers live (inside the installed package): a trained run's
    policy as a small weights-only file, taken by name (`services/learner/controllers.py`)."""
    return Path(str(resources.files("paramimic") / "data" / "controllers"))


def shipped_names() -> list[str]:
    folder = shipped_dir()
    return sorted(p.stem for p in folder.glob(f"*{SUFFIX}")) if folder.is_dir() else []


def shipped(name: str) -> Path | None:
    """The file of the shipped controller `name`, None if there is none."""
    if not name or "/" in name or name.startswith("."):
        return None
    path = shipped_dir() / f"{name}{SUFFIX}"
    return path if path.is_file() else None


def read(file: Path) -> dict:
    """One checkpoint file, loaded without running code (CheckpointError if unreadable)."""
    if not zipfile.is_zipfile(file):  # torch.save writes a zip archive; this is not one
        raise CheckpointError(f"{file} is damaged or truncated: not a torch checkpoint archive")
    if not verify(file) and file.parent.name == "checkpoints":
        warnings.warn(f"{file} has no manifest (written by an older release): not verified",
                      stacklevel=3)  # fmt: skip
    try:
        state = torch.load(file, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        raise CheckpointError(
            f"{file} is not a plain-data checkpoint and was not loaded (it would need to unpickle "
            f"objects, which can run code). If it is a checkpoint of an older paramimic (pickled "
            f"numpy) that you trust, convert it with `paramimic upgrade-checkpoint {file}`. ({e})"
        ) from None
    except (RuntimeError, EOFError, OSError, ValueError) as e:
        raise CheckpointError(f"{file} is damaged or truncated: {e}") from None
    if not isinstance(state, dict):
        raise CheckpointError(f"{file} holds {type(state).__name__}, not a checkpoint dict")
    state = decode(state)
    bad = non_finite({k: state.get(k) for k in WEIGHTS})
    if bad is not None:
        raise CheckpointError(f"{file} holds a non-finite value at {bad}")
    return state


def load(path: Path) -> dict:
    """The checkpoint at `path` (a file, or the latest of a run). If a run's latest.pt is damaged,
    the newest readable ckpt_*.pt is used with a warning; a refused (unsafe) file is never
    skipped over silently."""
    file = resolve(path)
    try:
        return read(file)
    except CheckpointError as e:
        if file.name != LATEST or "not a plain-data checkpoint" in str(e):
            raise
        for older in sorted(file.parent.glob("ckpt_*.pt"), key=_iteration, reverse=True):
            try:
                state = read(older)
            except CheckpointError:
                continue
            warnings.warn(f"{e}; using {older.name} instead", stacklevel=2)
            return state
        raise


def upgrade(file: Path) -> Path:
    """Rewrite a checkpoint of the older format (pickled numpy) as plain data. It is read with
    `weights_only` and only numpy's array and dtype constructors allowed, so a file that
    would construct anything else is refused here too (CheckpointError)."""
    file = resolve(file)
    try:
        with torch.serialization.safe_globals(_numpy_globals()):
            state = torch.load(file, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        raise CheckpointError(f"{file} holds more than numpy arrays; not converted ({e})") from None
    fd, tmp = tempfile.mkstemp(dir=file.parent, prefix=TMP_PREFIX, suffix=".pt")
    with os.fdopen(fd, "wb") as f:
        torch.save(encode(state), f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, file)  # in place: a run resumes from it
    _write_manifest(file)
    _fsync_dir(file.parent)
    return file


def _numpy_globals() -> list:
    """What unpickling numpy arrays and scalars needs, and nothing else."""
    multiarray = np._core.multiarray if hasattr(np, "_core") else np.core.multiarray
    dtypes = [type(np.dtype(t)) for t in _TORCH_DTYPES | {np.dtype("U1"), np.dtype("O")}]
    return [multiarray._reconstruct, multiarray.scalar, np.ndarray, np.dtype, *dtypes]


def load_policy(path: Path | str):
    """(state, config, policy in eval mode) of a run directory, a checkpoint file or a shipped
    controller's name: the controller a checkpoint holds, ready to act."""
    from paramimic.config import ExperimentConfig
    from paramimic.rl.networks import ActorCritic

    state = load(Path(path))
    cfg = ExperimentConfig.model_validate(state["config"])
    policy = ActorCritic(
        state["obs_dim"],
        state["act_dim"],
        cfg.ppo.hidden_sizes,
        0.0,
        value_hidden=cfg.ppo.value_hidden_sizes,
    )
    policy.load_state_dict(state["learner"]["policy"])
    policy.eval()
    return state, cfg, policy
