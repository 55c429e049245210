"""A training run's folder (``runs/NAME``): what ``dynpush train`` finds there, and how it writes into it.

- ``config.json``: the run's training config, written once per launch after every input (config, overrides,
  ``--init-from`` file, checkpoint) has been read and checked, so that a refused launch leaves the folder as it was;
- ``launches.jsonl``: one line per launch (command, processes, commit), written with ``config.json``;
- ``model_K.pt``: the checkpoints, each written to a temporary file in the folder and then renamed over its name,
  so that a checkpoint is either whole or absent; ``keep_checkpoints`` keeps the newest N;
- ``imitation.pt``: the checkpoint of ``dynpush imitate``, from which ``--resume`` starts CaT-PPO;
- ``progress.jsonl`` (every iteration), ``evaluations.jsonl`` (evaluations during training) and tensorboard's
  ``events.out.tfevents.*``, appended while the run trains.

A folder that holds a config or a checkpoint is a run: a new launch into it must say ``--resume``.
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import torch

from dynpush.errors import CorruptFileError, MissingFileError
from dynpush.sim.config import ConfigError

from .checkpoint_file import CheckpointError

CONFIG = "config.json"
IMITATION_CHECKPOINT = "imitation.pt"  # written by dynpush imitate; CaT-PPO starts from it


def checkpoints(run_dir: Path) -> list[Path]:
    """The run's ``model_K.pt``, oldest (smallest K) first."""
    return sorted(Path(run_dir).glob("model_*.pt"), key=lambda p: int(p.stem.split("_")[1]))


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The run's ``model_K.pt`` with the largest K; before the first one, its imitation checkpoint (if any)."""
    candidates = resume_candidates(run_dir)
    return candidates[0] if candidates else None


def resume_candidates(run_dir: Path) -> list[Path]:
    """The checkpoints a resumed run may start from, newest first: ``model_K.pt`` by K, then ``imitation.pt``."""
    imitation = Path(run_dir) / IMITATION_CHECKPOINT
    return checkpoints(run_dir)[::-1] + ([imitation] if imitation.exists() else [])


def check_new_run(run_dir: Path) -> None:
    """Raises a ConfigError unless ``run_dir`` is free for a new run (no config, no checkpoint in it)."""
    if (Path(run_dir) / CONFIG).exists() or resume_candidates(run_dir):
        raise ConfigError(f"{run_dir} holds a run already (config.json or checkpoints): continue it with --resume,"
                          " or choose another --name")


def load_newest_readable(run_dir: Path, load: Callable[[Path], object]) -> tuple[Path, list[str]]:
    """Calls ``load`` on the newest checkpoint of ``run_dir`` (:func:`resume_candidates`) that it reads (``load``
    raises a CheckpointError for a truncated or foreign file); returns that checkpoint and one note per newer one
    it skipped.

    Raises a MissingFileError when the folder has no checkpoint, a CheckpointError when ``load`` reads none.
    """
    candidates = resume_candidates(run_dir)
    if not candidates:
        raise MissingFileError(f"--resume: no model_*.pt or {IMITATION_CHECKPOINT} in {run_dir}")
    skipped = []
    for path in candidates:
        try:
            load(path)
        except CheckpointError as error:
            skipped.append(f"{path.name} ({str(error).splitlines()[0]})")
            continue
        return path, skipped
    raise CheckpointError(f"--resume: no readable checkpoint in {run_dir}: {'; '.join(skipped)}")


def save_checkpoint(state: dict, path: Path, keep: int = 0) -> None:
    """Writes ``state`` to ``path`` atomically (a temporary file in the same folder, then renamed over ``path``), so
    an interrupted write never leaves a truncated checkpoint; then keeps only the newest ``keep`` ``model_K.pt`` of
    the folder (0: all)."""
    path = Path(path)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as f:
            torch.save(state, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    if keep:
        for old in checkpoints(path.parent)[:-keep]:
            old.unlink()


def read_json(path: Path) -> dict:
    """The JSON object in ``path`` (a run's ``config.json``, ``imitation_config.json``); a MissingFileError or
    CorruptFileError naming the file otherwise."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise MissingFileError(f"{path} not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CorruptFileError(f"{path} is not readable JSON: {error}") from error
    if not isinstance(data, dict):
        raise CorruptFileError(f"{path} holds a JSON {type(data).__name__}, not an object")
    return data


def read_run_config(run_dir: Path) -> dict:
    """The JSON object of a run folder's ``config.json``; a MissingFileError saying the folder is no run without it."""
    path = Path(run_dir) / CONFIG
    if not path.exists():
        raise MissingFileError(f"{path} not found: {run_dir} is not a dynpush run folder")
    return read_json(path)


def write_config(run_dir: Path, config: dict) -> None:
    """Writes the run's ``config.json`` (creating the folder)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / CONFIG).write_text(json.dumps(config, indent=2))


def source_commit() -> str | None:
    """The git commit of the dynpush sources (with ``-dirty`` when they have uncommitted changes), or None."""
    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root, capture_output=True,
                               text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return commit + ("-dirty" if dirty else "")


def record_launch(run_dir: Path, command: str | None, procs: int, resume: bool, init_from: Path | None = None) -> None:
    """Appends this launch (the ``dynpush train`` command line, processes, commit, time and the checkpoint a new
    run started from) to ``launches.jsonl``."""
    record = {"command": command, "processes": procs, "resume": resume, "commit": source_commit(),
              "torch": torch.__version__, "time": time.time()}
    if init_from is not None:
        record["init_from"] = str(Path(init_from).resolve())
    with open(run_dir / "launches.jsonl", "a") as f:
        f.write(json.dumps(record) + "\n")
