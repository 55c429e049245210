"""A learned locomotion policy run by the runtime: 6D base command -> 12 leg joint position targets.

Used with ``locomotion.mode: onnx``. The observation is the concatenation of ``scale * term`` for
the configured terms (``locomotion_layout.LOCOMOTION_TERMS``), all from the robot state (state estimator and
IMU, never mocap, so locomotion keeps standing when mocap is lost):

- ``base_linear_velocity_b`` (3) [m/s], ``base_angular_velocity_b`` (3) [rad/s]: base frame
- ``projected_gravity_b`` (3): ``R_imu^T (0, 0, -1)``
- ``base_command`` (6): the absolute command (vx, vy, yaw rate, roll, pitch, height)
- ``leg_joint_position`` (12): ``q_leg - default_joint_positions`` [rad]; ``leg_joint_velocity`` (12)
- ``last_leg_actions`` (12): the previous network output
- ``arm_joint_position`` (5): ``q_arm - arm default`` (policy contract) [rad]; ``arm_joint_velocity`` (5)

Leg targets = ``default_joint_positions + action_scale * output``.

A ``locomotion.onnx`` written by ``dynpush export`` from a ``dynpush train --task locomotion`` run carries
its contract in the metadata key ``locomotion_contract`` (:func:`locomotion_contract`): the observation
terms and scales, joint names and order, default positions and action scale it was trained with. The
runtime refuses a config that disagrees with it (:func:`check_locomotion_contract`).
"""

from __future__ import annotations

import json

import numpy as np

from .config import LocomotionTerm, OnnxLocomotionConfig
from .contract import PolicyContract
from .errors import StartupError
from .locomotion_layout import LOCOMOTION_TERMS, NUM_LEG_JOINTS
from .observation import quat_to_matrix
from .packets import Proprioception
from .policy import OnnxModel

LOCOMOTION_CONTRACT_KEY = "locomotion_contract"


def locomotion_contract(cfg: OnnxLocomotionConfig, **extra) -> dict[str, str]:
    """ONNX metadata describing a locomotion network as ``cfg`` runs it (``extra``: further JSON values such as
    command limits, gains, control period and the training config)."""
    contract = {
        "observation": [{"name": t.name, "scale": t.scale} for t in cfg.observation],
        "joint_names": list(cfg.joint_names),
        "default_joint_positions": [float(v) for v in cfg.default_joint_positions],
        "action_scale": float(cfg.action_scale),
        **extra,
    }
    return {LOCOMOTION_CONTRACT_KEY: json.dumps(contract)}


def read_locomotion_contract(path: str) -> tuple[OnnxLocomotionConfig, dict]:
    """The runtime's ``locomotion.onnx`` section of an exported file (``dynpush export`` of a locomotion run) and
    its whole contract (command limits, joint limits, gains, training config)."""
    import onnxruntime as ort

    try:
        metadata = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).get_modelmeta().custom_metadata_map
    except Exception as error:  # onnxruntime raises its own exception types for unreadable models
        raise StartupError(f"locomotion.onnx: cannot load {path}: {error}") from error
    if LOCOMOTION_CONTRACT_KEY not in metadata:
        raise StartupError(f"{path} has no {LOCOMOTION_CONTRACT_KEY} metadata: not exported by dynpush from a locomotion run")
    contract = json.loads(metadata[LOCOMOTION_CONTRACT_KEY])
    missing = sorted({"observation", "joint_names", "default_joint_positions", "action_scale", "joint_lower",
                      "joint_upper"} - set(contract))
    if missing:
        raise StartupError(f"{path}: {LOCOMOTION_CONTRACT_KEY} lacks {missing}; export the run again with this dynpush")
    section = OnnxLocomotionConfig(
        path=str(path),
        observation=[LocomotionTerm(name=t["name"], scale=float(t["scale"])) for t in contract["observation"]],
        joint_names=list(contract["joint_names"]),
        default_joint_positions=[float(v) for v in contract["default_joint_positions"]],
        action_scale=float(contract["action_scale"]),
    )
    return section, contract


def check_locomotion_contract(metadata: dict[str, str], cfg: OnnxLocomotionConfig) -> None:
    """Raises :class:`StartupError` listing every field where ``cfg`` disagrees with the file's contract (if any)."""
    if LOCOMOTION_CONTRACT_KEY not in metadata:
        return  # a network from elsewhere: the config alone describes it
    try:
        contract = json.loads(metadata[LOCOMOTION_CONTRACT_KEY])
        trained = {
            "observation": [(str(t["name"]), float(t["scale"])) for t in contract["observation"]],
            "joint_names": [str(n) for n in contract["joint_names"]],
            "default_joint_positions": [float(v) for v in contract["default_joint_positions"]],
            "action_scale": float(contract["action_scale"]),
        }
    except (ValueError, KeyError, TypeError) as error:
        raise StartupError(f"locomotion.onnx: malformed {LOCOMOTION_CONTRACT_KEY} metadata ({error})") from error
    configured = {
        "observation": [(t.name, float(t.scale)) for t in cfg.observation],
        "joint_names": list(cfg.joint_names),
        "default_joint_positions": [float(v) for v in cfg.default_joint_positions],
        "action_scale": float(cfg.action_scale),
    }
    problems = []
    for name, value in trained.items():
        mine = configured[name]
        if name in ("default_joint_positions", "action_scale"):  # numbers: equal within float tolerance
            same = np.shape(mine) == np.shape(value) and np.allclose(mine, value, atol=1e-6)
        else:
            same = mine == value
        if not same:
            problems.append(f"locomotion.onnx.{name}: config has {mine}, the network was trained with {value}")
    if problems:
        raise StartupError("locomotion config does not match locomotion.onnx: " + "; ".join(problems))

_GRAVITY = np.array([0.0, 0.0, -1.0])


class OnnxLocomotion:
    def __init__(self, cfg: OnnxLocomotionConfig, contract: PolicyContract):
        self.model = OnnxModel(cfg.path, cfg.input_name, cfg.observation_size, cfg.output_name, NUM_LEG_JOINTS,
                               "locomotion.onnx")
        check_locomotion_contract(self.model.metadata, cfg)
        self._terms = []
        start = 0
        for term in cfg.observation:
            size = LOCOMOTION_TERMS[term.name]
            self._terms.append((term.name, term.scale, slice(start, start + size)))
            start += size
        self.default_joint_positions = np.asarray(cfg.default_joint_positions, dtype=np.float64)
        self._scale = cfg.action_scale
        self._arm_default = np.asarray(contract.arm_default_joint_positions, dtype=np.float64)
        self.last_actions = np.zeros(NUM_LEG_JOINTS)

    def _term(self, name: str, state: Proprioception, base_command: np.ndarray) -> np.ndarray:
        if name == "projected_gravity_b":
            return quat_to_matrix(state.base_quat_xyzw).T @ _GRAVITY
        if name == "leg_joint_position":
            return state.leg_q - self.default_joint_positions
        if name == "arm_joint_position":
            return state.arm_q - self._arm_default
        return {
            "base_linear_velocity_b": state.base_linear_velocity_b,
            "base_angular_velocity_b": state.base_angular_velocity_b,
            "base_command": base_command,
            "leg_joint_velocity": state.leg_qd,
            "last_leg_actions": self.last_actions,
            "arm_joint_velocity": state.arm_qd,
        }[name]

    def step(self, state: Proprioception, base_command: np.ndarray) -> np.ndarray:
        """Leg joint targets (12) [rad] for ``base_command``; the observation stays in ``model.input``."""
        observation = self.model.input[0]
        for name, scale, columns in self._terms:
            observation[columns] = scale * self._term(name, state, base_command)
        actions = self.model.run()
        self.last_actions = actions.astype(np.float64)
        return self.default_joint_positions + self._scale * self.last_actions
