"""Training configuration of the locomotion task (``dynpush train --task locomotion``; docs/legged.md).

Same learner as the push task (rsl_rl PPO + our CaT subclass, ``policies/runner.py``); only the environment,
the network sizes and the ``p_max`` curricula differ.

The defaults are the recipe that walks on this robot (docs/legged.md; the runs in
docs/experiments/legged_fidelity.md, "A walking gait under the disturbances"): the gait forms without disturbances
and without constraint terminations, then the random arm motions and base pushes grow in (``disturbance_ramp``).
The constraints are computed and logged, but their ``p_max`` is 0: every run with CaT's (Chane-Sane et al.,
IROS 2024: collisions hard with p_max 1, the others soft with p_max 0.05 -> 0.25), from scratch or from a walking
policy, learned to stand (docs/experiments/legged_fidelity.md).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from dynpush.kernels.locomotion.constraints import CONSTRAINT_GROUPS
from dynpush.sim.config import ConfigError
from dynpush.sim.locomotion_config import LocomotionEnvConfig

from .schedules import DisturbanceRampConfig
from .overrides import config_from_dict
from .training import PRESETS, NetworkConfig, PPOConfig, rsl_rl_runner_cfg


def _no_terminations() -> dict[str, tuple[float, float]]:
    return {name: (0.0, 0.0) for name, _ in CONSTRAINT_GROUPS}


@dataclass
class LocomotionTrainConfig:
    task: str = "locomotion"  # tells a run's config.json from a push run's (policies/tasks.py: task_of_config)
    preset: str = "cpu"
    env: LocomotionEnvConfig = field(default_factory=LocomotionEnvConfig)
    iterations: int = 1500  # ~37 M world-steps at 1024 worlds x 24 steps
    num_steps_per_env: int = 24  # legged_gym
    save_interval: int = 50
    ppo: PPOConfig = field(default_factory=lambda: PPOConfig(entropy_coef=0.01))  # legged_gym: entropy 0.01
    network: NetworkConfig = field(default_factory=lambda: NetworkConfig(actor_hidden=(512, 256, 128),  # legged_gym
                                                                          critic_hidden=(512, 256, 128),
                                                                          init_noise_std=0.5))  # ours: the runs that walked
    p_max: dict[str, tuple[float, float]] = field(default_factory=_no_terminations)  # see the module docstring
    p_max_ramp_fraction: float = 0.5  # of the run over which p_max goes from initial to final
    # Iterations (start, end) over which the random arm motions and base pushes grow from none to their full
    # size (ours, schedules.DisturbanceRampConfig): the gait forms first, then keeps walking while they grow.
    disturbance_ramp: tuple[int, int] = (250, 400)

    @staticmethod
    def preset_config(name: str) -> LocomotionTrainConfig:
        if name == "paper":  # the push task's GPU scale
            return LocomotionTrainConfig(preset=name, env=LocomotionEnvConfig(num_envs=4096, device="cuda:0",
                                                                             randomize_first_episode_length=True))
        if name == "cpu":
            return LocomotionTrainConfig(preset=name, env=LocomotionEnvConfig(num_envs=1024, randomize_first_episode_length=True))
        raise ConfigError(f"preset must be one of {PRESETS}, got {name!r}")

    def validate(self) -> LocomotionTrainConfig:
        if self.task != "locomotion":
            raise ConfigError(f"task must be 'locomotion', got {self.task!r}")
        self.env.validate()
        for name in ("iterations", "num_steps_per_env", "save_interval"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(f"{name} must be an integer >= 1, got {getattr(self, name)!r}")
        groups = {name for name, _ in CONSTRAINT_GROUPS}
        if set(self.p_max) != groups:
            raise ConfigError(f"p_max must name exactly the constraint groups {sorted(groups)}, got {sorted(self.p_max)}")
        for name, pair in self.p_max.items():
            if len(pair) != 2 or not all(0.0 <= p <= 1.0 for p in pair):
                raise ConfigError(f"p_max[{name!r}] must be (initial, final) within [0, 1], got {pair!r}")
        if not 0.0 <= self.p_max_ramp_fraction <= 1.0:
            raise ConfigError(f"p_max_ramp_fraction must lie in [0, 1], got {self.p_max_ramp_fraction!r}")
        if len(self.disturbance_ramp) != 2:
            raise ConfigError(f"disturbance_ramp must be (start, end) iterations, got {self.disturbance_ramp!r}")
        DisturbanceRampConfig(*self.disturbance_ramp).validate()
        self.ppo.validate()
        self.network.validate()
        return self

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @staticmethod
    def from_dict(data: dict) -> LocomotionTrainConfig:
        # Runs from before the ramp existed had their full disturbances from the first iteration, and one arm
        # amplitude for every joint.
        data = {"disturbance_ramp": (0, 0), **data}
        if "p_max" in data:  # runs from before the foot contact force constraint did not terminate on it
            data["p_max"] = {**_no_terminations(), **data["p_max"]}
        rewards = data.get("env", {}).get("rewards")
        if rewards is not None and "action_rate_weight" not in rewards:  # runs from before the penalty had none
            data["env"] = {**data["env"], "rewards": {**rewards, "action_rate_weight": 0.0}}
        randomization = data.get("env", {}).get("randomization")
        if randomization is not None:  # new dicts: the caller's stays as it is
            if isinstance(randomization.get("arm_amplitude"), (int, float)):
                randomization = {**randomization, "arm_amplitude": (float(randomization["arm_amplitude"]),) * 5}
            if "ee_force_max" not in randomization:  # runs from before the end-effector forces had none
                randomization = {**randomization, "ee_force_max": 0.0}
            data["env"] = {**data["env"], "randomization": randomization}
        return config_from_dict(LocomotionTrainConfig, data)

    def check_onnx_start(self, init_from: Path) -> None:
        """A locomotion run starts from a checkpoint only (it has no critic warm-up): always raises a ConfigError."""
        raise ConfigError(f"--init-from {init_from}: an ONNX file can start a push run only; a locomotion run starts"
                          " from a checkpoint (model_K.pt)")

    def make_env(self, env: LocomotionEnvConfig):
        from dynpush.sim.locomotion_env import LocomotionEnv

        return LocomotionEnv(env)

    def runner_cfg(self) -> dict:
        """The rsl_rl runner configuration."""
        return {
            **rsl_rl_runner_cfg(self.num_steps_per_env, self.save_interval, self.ppo, self.network),
            "schedule": {
                "scale_with_run_length": False,
                "reach": None,
                "constraints": {"p_max": {name: tuple(pair) for name, pair in self.p_max.items()},
                                "ramp_iterations": int(self.p_max_ramp_fraction * self.iterations)},
                "disturbance": dataclasses.asdict(DisturbanceRampConfig(*self.disturbance_ramp)),
            },
        }
