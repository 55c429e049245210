"""What the sim-to-sim simulator saw, step by step, so that the runtime's chain can be compared with the simulation.

``dynpush sim2sim --record FILE`` makes the simulator (``dynpush.policies.sim2sim``) write ``FILE`` (``.npz``) when it
ends. Per simulator step ``k`` (arrays of ``S`` rows, taken before the step, i.e. of the state the runtime acted on at
its tick ``k``):

- ``step`` (S,), ``episode`` (S,): the episode running, -1 before the first;
- ``policy_obs`` (S, 54): the push observation the environment's kernel computes from that state, term for term what
  the runtime's numpy builder should have computed (its ``last_actions`` are the environment's own, zero here:
  sim-to-sim commands carry no policy actions);
- ``locomotion_obs`` (S, 61), legged robot only: the kernel's locomotion observation with the command the runtime
  sent (its ``last_leg_actions`` stay zero for the same reason);
- ``base_pose``, ``object_pose`` (S, 7): world position [m] and quaternion (x, y, z, w);
- ``meta``: JSON of the run's ``policy``, ``seed`` and environment ``overrides``.

And per episode ``i``, ``start{i}/NAME``: the environment's full state (``state_dict``) right after the episode was
drawn, from which :func:`dynpush.policies.chain_replay.replay_in_simulation` runs the same episode in the simulation.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dynpush.errors import MissingFileError, UserError

START_PREFIX = "start"


class ChainRecordError(UserError, ValueError):
    """A file that is not a sim-to-sim record."""


class StepRecorder:
    """Collects the record of one sim-to-sim run (see the module docstring) and writes it."""

    def __init__(self, env, probe, meta: dict):
        self.env, self.probe, self.meta = env, probe, meta
        self.legged = env.cfg.legged.enabled
        self.rows: dict[str, list[np.ndarray]] = {"step": [], "episode": [], "policy_obs": [], "base_pose": [],
                                                  "object_pose": []}
        if self.legged:
            self.rows["locomotion_obs"] = []
        self.starts: list[dict[str, np.ndarray]] = []

    def episode_started(self) -> None:
        """The environment holds a freshly drawn episode (after ``reset`` or an auto-reset inside a step)."""
        self.starts.append(self.env.state_dict())

    def before_step(self, step: int) -> None:
        """The state the runtime acted on: its pose, and the actor observation the kernel computed from it."""
        rows = self.rows
        rows["step"].append(np.int64(step))
        rows["episode"].append(np.int64(len(self.starts) - 1))
        rows["policy_obs"].append(self.env.policy_obs_t[0].numpy().copy())
        rows["base_pose"].append(self.probe.base()[0].copy())
        rows["object_pose"].append(self.probe.object()[0].copy())

    def after_commands(self) -> None:
        """The locomotion observation the step's first graph computed from the same state and the sent command."""
        if self.legged:
            self.rows["locomotion_obs"].append(self.env.leg_obs.numpy()[0].copy())

    def write(self, path: str | Path) -> None:
        arrays = {name: np.asarray(rows) for name, rows in self.rows.items()} | {"meta": np.array(json.dumps(self.meta))}
        for i, state in enumerate(self.starts):
            arrays |= {f"{START_PREFIX}{i}/{name}": value for name, value in state.items()}
        np.savez_compressed(path, **arrays)


class ChainRecord:
    """A record read back: per-step ``rows`` (name -> array) and the episodes' ``starts`` (state dicts)."""

    def __init__(self, rows: dict[str, np.ndarray], starts: list[dict[str, np.ndarray]]):
        self.rows, self.starts = rows, starts

    def episode_rows(self, name: str, episode: int) -> np.ndarray:
        """``name``'s rows of the steps of ``episode``."""
        return self.rows[name][self.rows["episode"] == episode]


def read_record(path: str | Path) -> ChainRecord:
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"sim-to-sim record {path} does not exist")
    try:
        with np.load(path) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError) as error:
        raise ChainRecordError(f"{path}: not a sim-to-sim record ({error})") from None
    missing = {"step", "episode", "policy_obs", "base_pose", "object_pose", "meta"} - set(arrays)
    if missing:
        raise ChainRecordError(f"{path}: not a sim-to-sim record (lacks {sorted(missing)})")
    rows = {name: value for name, value in arrays.items() if "/" not in name}
    starts: dict[int, dict[str, np.ndarray]] = {}
    for name, value in arrays.items():
        if name.startswith(START_PREFIX) and "/" in name:
            index, key = name[len(START_PREFIX):].split("/", 1)
            starts.setdefault(int(index), {})[key] = value
    return ChainRecord(rows, [starts[i] for i in sorted(starts)])
