"""The ONNX contract between training and deployment: what ``policy.onnx`` carries besides its graph.

The exported file has one input ``obs`` [1, 54] float32 (un-normalised observation; the normaliser is
inside the graph) and one output ``actions`` [1, 11] float32 (the deterministic mean). Its
``metadata_props`` hold :class:`PolicyContract` as string key/values (JSON for structured values), so
the runtime can check a policy against its configuration before it moves a robot. No heavy imports
(numpy only): used by the exporter (``dynpush.policies``) and the runtime alike.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields

from dynpush.errors import UserError

from .actions import ACTION_LAYOUT, BASE_COMMAND_NAMES, ActionMapping, ActionScaling
from .observation import NUM_ACTIONS, POLICY_OBSERVATION_LAYOUT

CONTRACT_VERSION = "1"
INPUT_NAME = "obs"
OUTPUT_NAME = "actions"
QUATERNION_ORDER = "xyzw"
OBSERVATION_FRAMES = {
    "ee_to_object_b": "base frame, m: R_b^T (p_ee - p_object)",
    "object_rotation_b": "R_b^T R_object, row-major",
    "arm_joint_position": "rad, relative to arm_default_joint_positions",
    "base_linear_velocity_b": "base frame, m/s",
    "base_angular_velocity_b": "base frame, rad/s",
    "arm_joint_velocity": "rad/s",
    "projected_gravity_b": "base frame, unit vector R_b^T (0, 0, -1)",
    "object_to_goal_b": "base frame, m: R_b^T (p_goal - p_object)",
    "goal_rotation_o": "R_object^T R_goal, row-major",
    "last_actions": "the previous clipped policy output (11)",
}


class ContractError(UserError, ValueError):
    """A policy file whose contract is missing, malformed or does not match what the runtime expects."""


@dataclass
class PolicyContract:
    """Everything the runtime needs to turn measurements into observations and actions into commands."""

    observation_layout: list[tuple[str, int]] = field(default_factory=lambda: [list(t) for t in POLICY_OBSERVATION_LAYOUT])
    observation_noise: dict[str, float] = field(default_factory=dict)  # training noise half-widths (not applied at runtime)
    action_layout: list[tuple[str, int]] = field(default_factory=lambda: [list(t) for t in ACTION_LAYOUT])
    base_command_names: list[str] = field(default_factory=lambda: list(BASE_COMMAND_NAMES))
    base_command_default: list[float] = field(default_factory=list)  # (6,)
    base_command_scale: list[float] = field(default_factory=list)  # (6,)
    base_command_lower: list[float] = field(default_factory=list)  # (6,) limits of the locomotion command
    base_command_upper: list[float] = field(default_factory=list)
    arm_joint_names: list[str] = field(default_factory=list)  # (5,) controlled joints, in action order
    arm_default_joint_positions: list[float] = field(default_factory=list)  # (5,) rad
    arm_action_scale: float = 0.0  # rad per unit action
    arm_joint_lower: list[float] = field(default_factory=list)  # rad
    arm_joint_upper: list[float] = field(default_factory=list)
    arm_joint_velocity_limit: list[float] = field(default_factory=list)  # rad/s
    frozen_joint_name: str = ""
    frozen_joint_position: float = 0.0
    action_clip: float = 0.0
    control_period_s: float = 0.02
    success_distance_m: float = 0.1
    success_angle_rad: float = 0.17453292519943295
    quaternion_order: str = QUATERNION_ORDER
    observation_frames: dict[str, str] = field(default_factory=lambda: dict(OBSERVATION_FRAMES))
    dynpush_version: str = ""
    training_config: dict = field(default_factory=dict)
    training_config_sha256: str = ""
    contract_version: str = CONTRACT_VERSION

    def action_mapping(self) -> ActionMapping:
        """How this policy's actions become the base command and the arm targets (``actions.py``)."""
        return ActionMapping(ActionScaling(self.base_command_default, self.base_command_scale),
                             ActionScaling(self.arm_default_joint_positions, self.arm_action_scale), self.action_clip)

    def to_metadata(self) -> dict[str, str]:
        """String key/values for ONNX ``metadata_props`` (JSON for non-strings)."""
        return {k: v if isinstance(v, str) else json.dumps(v) for k, v in asdict(self).items()}

    @staticmethod
    def from_metadata(metadata: dict[str, str]) -> PolicyContract:
        """Parses ``metadata_props``; raises :class:`ContractError` naming a missing or malformed key."""
        values = {}
        for f in fields(PolicyContract):
            if f.name not in metadata:
                raise ContractError(f"policy metadata lacks {f.name!r} (not a dynpush policy, or too old)")
            text = metadata[f.name]
            if f.type == "str":
                values[f.name] = text
                continue
            try:
                values[f.name] = json.loads(text)
            except json.JSONDecodeError as error:
                raise ContractError(f"policy metadata {f.name!r} is not valid JSON: {error}") from error
        contract = PolicyContract(**values)
        try:
            contract.validate()
        except ContractError:
            raise
        except (TypeError, ValueError) as error:  # a value of the wrong kind, e.g. a number where a list belongs
            raise ContractError(f"policy metadata is malformed: {error}") from error
        return contract

    def validate(self) -> None:
        if self.contract_version != CONTRACT_VERSION:
            raise ContractError(f"contract_version {self.contract_version!r} is not supported (expected {CONTRACT_VERSION!r})")
        layout = [(str(n), int(s)) for n, s in self.observation_layout]
        if layout != [(n, s) for n, s in POLICY_OBSERVATION_LAYOUT]:
            raise ContractError(f"observation_layout {layout} differs from this runtime's {list(POLICY_OBSERVATION_LAYOUT)}")
        if sum(s for _, s in self.action_layout) != NUM_ACTIONS:
            raise ContractError(f"action_layout must total {NUM_ACTIONS} entries, got {self.action_layout}")
        for name, size in (("base_command_default", 6), ("base_command_scale", 6), ("base_command_lower", 6),
                           ("base_command_upper", 6), ("arm_joint_names", 5), ("arm_default_joint_positions", 5),
                           ("arm_joint_lower", 5), ("arm_joint_upper", 5), ("arm_joint_velocity_limit", 5)):
            if not isinstance(getattr(self, name), list) or len(getattr(self, name)) != size:
                raise ContractError(f"{name} must have {size} entries, got {getattr(self, name)!r}")
        if self.quaternion_order != QUATERNION_ORDER:
            raise ContractError(f"quaternion_order must be {QUATERNION_ORDER!r}, got {self.quaternion_order!r}")
        self._validate_numbers()

    def _validate_numbers(self) -> None:
        """The numbers the runtime turns into commands: finite, scales and thresholds > 0, every default within its
        limits (a NaN or inverted limit here would reach the robot)."""
        for name in ("base_command_default", "base_command_lower", "base_command_upper", "arm_default_joint_positions",
                     "arm_joint_lower", "arm_joint_upper"):
            for i, value in enumerate(getattr(self, name)):
                _check_number(f"{name}[{i}]", value)
        for name in ("base_command_scale", "arm_joint_velocity_limit"):
            for i, value in enumerate(getattr(self, name)):
                _check_number(f"{name}[{i}]", value, positive=True)
        for name in ("arm_action_scale", "action_clip", "control_period_s", "success_distance_m", "success_angle_rad"):
            _check_number(name, getattr(self, name), positive=True)
        _check_number("frozen_joint_position", self.frozen_joint_position)
        _check_within("base_command_default", self.base_command_default, "base_command", self.base_command_lower,
                      self.base_command_upper)
        _check_within("arm_default_joint_positions", self.arm_default_joint_positions, "arm_joint", self.arm_joint_lower,
                      self.arm_joint_upper)


def _check_number(name: str, value: object, positive: bool = False) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (positive and not value > 0.0):
        raise ContractError(f"{name} must be a finite number{' > 0' if positive else ''}, got {value!r}")


def _check_within(name: str, values: list[float], limits: str, lower: list[float], upper: list[float]) -> None:
    """``lower[i] <= values[i] <= upper[i]``; the error names the entry."""
    for i, (value, lo, hi) in enumerate(zip(values, lower, upper)):
        if not lo <= hi:
            raise ContractError(f"{limits}_lower[{i}] {lo} must be <= {limits}_upper[{i}] {hi}")
        if not lo <= value <= hi:
            raise ContractError(f"{name}[{i}] {value} must lie within {limits}_lower/_upper [{lo}, {hi}]")


