"""On-policy runner for CaT-PPO: rsl_rl's OnPolicyRunner plus the push task's iteration schedules.

rsl_rl's learning loop is used unchanged. :class:`~dynpush.policies.cat_ppo.CaTPPO` reads ``extras["constraints"]``
in its ``process_env_step`` and adds its statistics to the extras that rsl_rl's logger averages per iteration
(``CaT/mean_delta``, ``CaT/violation_rate/<group>``). This runner only builds CaT-PPO and, at the start of every
iteration, applies the ``p_max`` curricula and the reach-reward weight (:mod:`dynpush.policies.schedules`).
"""

from __future__ import annotations

from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner

from dynpush.policies.cat_ppo import CaTPPO
from dynpush.policies.schedules import ScheduleConfig, p_max_at, reach_weight_at


class CaTOnPolicyRunner(OnPolicyRunner):
    """On-policy runner for CaT-PPO with per-iteration schedules.

    The environment must provide ``env.constraint_groups`` (``(name, dim)`` in column order), ``extras["constraints"]``
    every step, and ``env.set_reward_weight(name, weight)``. ``train_cfg`` is rsl_rl's runner config; its optional
    ``"schedule"`` entry holds :class:`~dynpush.policies.schedules.ScheduleConfig` fields as a nested dict, and
    ``train_cfg["algorithm"]["class_name"]`` defaults to :class:`CaTPPO`.
    """

    alg: CaTPPO
    """The CaT-PPO algorithm."""

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | None = None, device: str = "cpu") -> None:
        """Construct the runner, CaT-PPO and the schedules."""
        train_cfg["algorithm"].setdefault("class_name", f"{CaTPPO.__module__}:{CaTPPO.__name__}")
        super().__init__(env, train_cfg, log_dir, device)
        if not isinstance(self.alg, CaTPPO):
            raise TypeError(f"CaTOnPolicyRunner needs a CaTPPO algorithm, got {type(self.alg).__name__}.")
        self.schedule_cfg = ScheduleConfig.from_dict(train_cfg.get("schedule", {}))

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = False) -> None:
        """Run rsl_rl's learning loop; the schedules follow iterations ``[start, start + num_learning_iterations)``."""
        start_it = self.current_learning_iteration
        total_it = start_it + num_learning_iterations
        iterations = iter(range(start_it, total_it))
        self.alg.on_rollout_start = lambda: self.apply_schedules(next(iterations), total_it)
        super().learn(num_learning_iterations, init_at_random_ep_len)

    def apply_schedules(self, iteration: int, total_iterations: int) -> None:
        """Set ``p_max`` and the reach-reward weight for ``iteration`` of a run of ``total_iterations``."""
        self.alg.set_p_max(p_max_at(iteration, total_iterations, self.schedule_cfg, self.env.constraint_groups))
        self.env.set_reward_weight("reach", reach_weight_at(iteration, total_iterations, self.schedule_cfg))
