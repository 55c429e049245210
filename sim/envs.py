"""The push environment of a config: the tracked base (:class:`~dynpush.sim.push_env.PushEnv`) or, with
``cfg.legged.enabled``, the legged robot (:class:`~dynpush.sim.legged_push_env.LeggedPushEnv`, a subclass).

The factory lives above both modules so that the base module never imports its subclass.
"""

from __future__ import annotations

from .config import PushEnvConfig
from .push_env import PushEnv


def make_push_env(cfg: PushEnvConfig) -> PushEnv:
    """The push environment of ``cfg``: the tracked base, or with ``cfg.legged.enabled`` the legged robot."""
    if cfg.legged.enabled:
        from .legged_push_env import LeggedPushEnv  # MuJoCo-Warp and the locomotion kernels: only when asked for

        return LeggedPushEnv(cfg)
    return PushEnv(cfg)
