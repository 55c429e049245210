"""The runtime's chain beside the simulation: the same episodes, the same states, the same observations.

A sim-to-sim record (``dynpush sim2sim --record``, :mod:`dynpush.policies.chain_record`) holds each episode's start
state and, per step, what the simulator's own kernels compute from the state the runtime acted on. Two comparisons:

- :func:`compare_observations`: the runtime's tick log against the record, term by term. The runtime's numpy builders
  are tested equal to the kernels on random states; here they meet the states of a real run, the command the runtime
  sent (its safety layer clips the base command to its limits) and the runtime's own action history, where the
  simulator only sees a policy at rest.
- :func:`replay_in_simulation`: each recorded episode again from its start state, with the push policy (and, legged,
  the locomotion policy) run inside the environment as ``dynpush eval`` runs them: the in-simulation outcome and base
  path beside the chain's. A difference in outcome on the same episode is a defect of the chain or of the sim-to-sim
  set-up (timing, action history), not of the policies.
"""

from __future__ import annotations

import json

import numpy as np
import torch

from dynpush.runtime.actions import ActionScaling
from dynpush.runtime.contract import PolicyContract
from dynpush.runtime.locomotion import clipped_outputs
from dynpush.runtime.locomotion_contract import LocomotionContract
from dynpush.runtime.locomotion_layout import LOCOMOTION_TERMS
from dynpush.runtime.observation import POLICY_OBSERVATION_LAYOUT
from dynpush.runtime.safety import State
from dynpush.runtime.tick_log import RecordLayout, TickLog
from dynpush.sim.envs import make_push_env

from .chain_record import ChainRecord
from .env_probe import EnvProbe
from .episodes import run_first_episodes
from .onnx_policy import OnnxPolicy
from .trained_env import env_config_for


PUSH_TERM_COLUMNS = RecordLayout(POLICY_OBSERVATION_LAYOUT).slices
LOCOMOTION_TERM_COLUMNS = RecordLayout(tuple(LOCOMOTION_TERMS.items())).slices


def _term_differences(logged: np.ndarray, simulated: np.ndarray, terms: dict[str, slice]
                      ) -> dict[str, dict[str, float]]:
    """Per term (name -> its columns): the largest and the median absolute difference over the rows."""
    out = {}
    for name, columns in terms.items():
        d = np.abs(logged[:, columns] - simulated[:, columns])
        out[name] = {"max": float(d.max()), "median": float(np.median(d))} if len(d) else {"max": None, "median": None}
    return out


def compare_observations(record: ChainRecord, log: TickLog) -> dict:
    """The runtime's push (and locomotion) observations of each tick against the kernels' of the same state.

    Tick ``k`` of the runtime acted on the state the simulator recorded before its step ``k`` (lock-step, or real time
    without skipped deadlines); ``alignment_error_m`` (the largest distance between the runtime's mocap base position
    and the recorded one at the same index, no mocap noise) says whether that pairing holds. Rows: ticks with a
    runtime observation during a recorded episode.
    """
    steps = record.rows["step"]
    ticks = log.column("tick")[:, 0].astype(np.int64)
    by_tick = {int(t): i for i, t in enumerate(ticks)}
    pairs = np.array([(by_tick[int(s)], i) for i, s in enumerate(steps) if int(s) in by_tick], dtype=np.int64)
    log_rows, rec_rows = pairs[:, 0], pairs[:, 1]
    alignment = np.linalg.norm(log.column("base_position")[log_rows] - record.rows["base_pose"][rec_rows, :3], axis=1)
    obs = log.column("obs")[log_rows]
    keep = np.isfinite(obs).all(axis=1) & (record.rows["episode"][rec_rows] >= 0)
    result = {"ticks_compared": int(keep.sum()),
              "alignment_error_m": float(alignment.max()) if len(alignment) else None,
              "push_observation": _term_differences(obs[keep], record.rows["policy_obs"][rec_rows][keep],
                                                    PUSH_TERM_COLUMNS)}
    if "locomotion_obs" in record.rows:
        result["locomotion_observation"] = _term_differences(
            log.column("locomotion_obs")[log_rows][keep], record.rows["locomotion_obs"][rec_rows][keep],
            LOCOMOTION_TERM_COLUMNS)
    return result


def _with_runtime_history(start: dict[str, np.ndarray], log: TickLog, tick: int) -> dict[str, np.ndarray]:
    """``start`` with the action history the runtime had at ``tick`` (its observations' previous actions), where the
    simulator's commands left the environment's own at rest: the same controller memory on both sides."""
    start = dict(start)
    row = int(np.flatnonzero(log.column("tick")[:, 0] == tick)[0])
    columns = PUSH_TERM_COLUMNS["last_actions"]
    last_actions = log.column("obs")[row, columns]
    start["task.actions"], start["policy_obs"] = start["task.actions"].copy(), start["policy_obs"].copy()
    start["task.actions"][0] = start["policy_obs"][0, columns] = last_actions
    if "leg_task.actions" in start:
        start["leg_task.actions"] = start["leg_task.actions"].copy()
        start["leg_task.actions"][0] = log.column("locomotion_obs")[row, LOCOMOTION_TERM_COLUMNS["last_leg_actions"]]
    return start


def safety_clamps(log: TickLog, contract: PolicyContract, locomotion: LocomotionContract | None = None
                  ) -> dict[str, float]:
    """Share of the PUSH ticks at which the runtime's safety layer sent other targets than the policies asked for
    (``CommandLimits.clamp``: base command, arm and leg joint ranges), per block: how often the policies ask for more
    than the limits. The environments clamp what they send to the same limits (``kernels/push/actions.py``,
    ``kernels/locomotion/actions.py``), so a replay in simulation receives the same clamped targets."""
    push = log.column("state")[:, 0] == State.PUSH
    mapping = contract.action_mapping()
    base, arm = mapping.commands(mapping.clipped(log.column("actions")[push]))
    shares = {"base_command": base, "arm_targets": arm}
    if locomotion is not None:  # leg targets as runtime/locomotion.py maps the network's outputs
        legs = ActionScaling(locomotion.default_joint_positions, locomotion.action_scale)
        shares["leg_targets"] = legs.targets(clipped_outputs(log.column("locomotion_actions")[push], contract.action_clip))
    return {name: float((np.abs(wanted - log.column(name)[push]).max(axis=1) > 1e-6).mean()) if push.any() else 0.0
            for name, wanted in shares.items()}


class _BasePath:
    """World 0's base position [m] (world) before every step of its first episode."""

    def __init__(self, probe: EnvProbe):
        self.probe = probe
        self.positions = [probe.base()[0, :3].copy()]

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        if bool(continuing[0]):
            self.positions.append(self.probe.base()[0, :3].copy())


def replay_in_simulation(record: ChainRecord, policy_path: str, locomotion_policy: str | None,
                         log: TickLog | None = None) -> list[dict]:
    """Every recorded episode from its start state, with the policies inside the environment (observation noise off,
    the record's seed and overrides, so that the base pushes fall at the same steps). With the runtime's tick ``log``
    each episode also starts with the runtime's action history (push and locomotion), else with the environment's
    (none, as ``dynpush eval``'s episodes start). Each runs in ``dynpush eval``'s episode loop. Per episode: the
    outcome as sim-to-sim reports it and the base position [m] (world) before every step, ``(steps, 3)``."""
    meta = json.loads(str(record.rows["meta"]))
    policy = OnnxPolicy(policy_path)
    overrides = list(meta["overrides"])
    if locomotion_policy:
        overrides.append(f"env.legged.locomotion_policy={locomotion_policy}")
    env = make_push_env(env_config_for(policy, 1, noise=False, seed=meta["seed"], overrides=overrides))
    probe = EnvProbe(env)
    episodes = []
    for i, start in enumerate(record.starts):
        if log is not None:
            start = _with_runtime_history(start, log, int(record.episode_rows("step", i)[0]))
        env.load_state_dict(start)
        path = _BasePath(probe)
        outcome = run_first_episodes(env, policy, [path], started=True)
        episodes.append({"success": bool(outcome.success[0]), "toppled": bool(outcome.toppled[0]),
                         "steps": int(outcome.length[0]), "fallen": bool(outcome.fallen[0]),
                         "base_position": np.array(path.positions)})
    return episodes


def path_divergence(chain: np.ndarray, simulated: np.ndarray, thresholds_m=(0.01, 0.05, 0.2)) -> dict:
    """How far the chain's base path (steps, 3) [m] runs from the simulation's over their common steps: the first step
    beyond each threshold (None: never) and the largest distance."""
    n = min(len(chain), len(simulated))
    distance = np.linalg.norm(chain[:n] - simulated[:n], axis=1)
    first = {f"{t:g}": (int(np.argmax(distance > t)) if (distance > t).any() else None) for t in thresholds_m}
    return {"common_steps": n, "max_m": float(distance.max()) if n else None, "first_step_beyond_m": first}
