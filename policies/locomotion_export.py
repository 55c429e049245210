"""ONNX export of a trained locomotion policy (``dynpush export`` of a ``--task locomotion`` run).

``locomotion.onnx``: input ``obs`` [1, 61] float32, the un-normalised observation in the layout of
``dynpush.kernels.locomotion.observations.POLICY_TERMS`` (every term of the runtime's ``LOCOMOTION_TERMS``, scale 1);
output ``actions`` [1, 12] float32, the deterministic mean before the environment's clip. Leg targets
``default + action_scale * actions`` in ``LEG_JOINT_NAMES`` order. The metadata holds its
:class:`~dynpush.runtime.locomotion_contract.LocomotionContract`: the runtime's
:class:`~dynpush.runtime.config.OnnxLocomotionConfig` fields (checked by the runtime at start-up) plus the
command limits, joint limits, PD gains, control period and training config.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

from dynpush.assets_usd import LEG_JOINT_NAMES
from dynpush.kernels.locomotion.observations import NUM_POLICY_OBS, POLICY_TERMS
from dynpush.kernels.locomotion.views import NUM_LEG_JOINTS
from dynpush.runtime.actions import BASE_COMMAND_NAMES
from dynpush.runtime.config import LocomotionTerm, OnnxLocomotionConfig
from dynpush.runtime.locomotion_contract import LocomotionContract

from .actor import load_actor
from .export import config_sha256, resolve_checkpoint, write_onnx
from .locomotion_train import LocomotionTrainConfig
from .run_folder import read_run_config

if TYPE_CHECKING:
    from dynpush.sim.legged_scene import LeggedRobotDescription


def runtime_section(cfg: LocomotionTrainConfig, robot: LeggedRobotDescription, path: str) -> OnnxLocomotionConfig:
    """The runtime's ``locomotion.onnx`` config section for a network trained with ``cfg`` on ``robot`` at ``path``."""
    return OnnxLocomotionConfig(
        path=path,
        observation=[LocomotionTerm(name=name, scale=1.0) for name, _ in POLICY_TERMS],
        joint_names=list(LEG_JOINT_NAMES),
        default_joint_positions=robot.leg_default.tolist(),
        action_scale=cfg.env.action_scale,
    )


def export_locomotion(run_dir: Path, checkpoint: str | None = None, out: Path | None = None) -> Path:
    """Exports a locomotion run's checkpoint (default: the latest) to ``run_dir / "locomotion.onnx"`` (or ``out``)."""
    from dynpush.sim.legged_scene import legged_robot_builder

    run_dir = Path(run_dir)
    # The locomotion config class directly, not the task registry's load_run_config: the registry's export hooks
    # import this module. A push run's config is a ConfigError here (its fields are no LocomotionTrainConfig's).
    cfg = LocomotionTrainConfig.from_dict(read_run_config(run_dir))
    checkpoint_path = resolve_checkpoint(run_dir, checkpoint)
    out = Path(out) if out is not None else run_dir / "locomotion.onnx"
    robot = legged_robot_builder()[1]
    training_config = json.loads(json.dumps(cfg.to_dict()))
    metadata = LocomotionContract.metadata(
        runtime_section(cfg, robot, out.name),
        command_names=list(BASE_COMMAND_NAMES),
        command_lower=list(cfg.env.commands.lower),
        command_upper=list(cfg.env.commands.upper),
        action_clip=cfg.env.action_clip,
        control_period_s=cfg.env.control_dt,
        joint_stiffness=robot.leg_stiffness.tolist(),
        joint_damping=robot.leg_damping.tolist(),
        joint_effort_limit=robot.leg_effort_limit.tolist(),
        joint_lower=robot.leg_lower.tolist(),
        joint_upper=robot.leg_upper.tolist(),
        checkpoint=checkpoint_path.name,
        training_config=training_config,
        training_config_sha256=config_sha256(training_config),
    )
    actor = load_actor(checkpoint_path, cfg, NUM_POLICY_OBS, NUM_LEG_JOINTS)
    write_onnx(actor, out, metadata,
               f"dynpush locomotion policy from {run_dir.name}/{checkpoint_path.name}; contract in metadata_props")
    return out
