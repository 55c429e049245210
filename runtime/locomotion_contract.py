"""The contract a ``locomotion.onnx`` carries: what its network reads and how its outputs become leg targets.

``dynpush export`` of a locomotion run writes it as JSON into the ONNX ``metadata_props`` under
``LOCOMOTION_CONTRACT_KEY`` (:meth:`LocomotionContract.metadata`). Both sides that run such a file read it here,
with :meth:`LocomotionContract.from_metadata`: the runtime (``locomotion.py``: one robot per tick, the observation
built from the robot state) and the simulator (``dynpush.sim.legged_push_env.LocomotionNetwork``: all worlds in one
call, the observation written by the Warp kernel). Its fields:

- ``observation``: the network's input terms in order, each entering as ``scale * term`` (``LOCOMOTION_TERMS``);
- ``joint_names``: the 12 leg joints in output order; ``default_joint_positions`` [rad] and ``action_scale`` [rad per
  unit output]: leg targets ``default_joint_positions + action_scale * output`` (``actions.ActionScaling``), the output
  clipped first at the push policy's ``action_clip`` by both sides;
- ``joint_lower``, ``joint_upper``: the leg joints' position limits [rad];
- ``values``: the whole document, which also holds the command names and limits, the action clip of the locomotion
  training, the control period [s], the PD gains, the checkpoint and the training config.

The runtime's ``locomotion.onnx`` config section (:class:`~.config.OnnxLocomotionConfig`) holds the first group
(:meth:`LocomotionContract.section`); the runtime refuses a config that disagrees with its file's contract
(:meth:`LocomotionContract.check`). onnxruntime is imported only to read a file (:meth:`LocomotionContract.read`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .config import LocomotionTerm, OnnxLocomotionConfig
from .errors import StartupError

LOCOMOTION_CONTRACT_KEY = "locomotion_contract"
REQUIRED_FIELDS = ("observation", "joint_names", "default_joint_positions", "action_scale", "joint_lower",
                   "joint_upper")


@dataclass(frozen=True)
class LocomotionContract:
    """A locomotion network's contract (module docstring)."""

    observation: tuple[tuple[str, float], ...]  # (term, scale), in input order
    joint_names: tuple[str, ...]  # (12,) in output order
    default_joint_positions: tuple[float, ...]  # (12,) [rad]
    action_scale: float  # [rad] per unit output
    joint_lower: tuple[float, ...]  # (12,) [rad]
    joint_upper: tuple[float, ...]  # (12,) [rad]
    values: dict  # the whole document, as stored

    @staticmethod
    def metadata(section: OnnxLocomotionConfig, **extra) -> dict[str, str]:
        """ONNX metadata of a network that ``section`` runs; ``extra``: the further JSON values (``joint_lower`` and
        ``joint_upper`` required; command limits, gains, control period, training config...)."""
        document = {
            "observation": [{"name": t.name, "scale": t.scale} for t in section.observation],
            "joint_names": list(section.joint_names),
            "default_joint_positions": [float(v) for v in section.default_joint_positions],
            "action_scale": float(section.action_scale),
            **extra,
        }
        return {LOCOMOTION_CONTRACT_KEY: json.dumps(document)}

    @staticmethod
    def from_metadata(metadata: dict[str, str], source: str) -> LocomotionContract:
        """The contract in an ONNX file's ``metadata_props``; a :class:`StartupError` naming ``source`` (the file)
        when it is missing, incomplete or malformed."""
        if LOCOMOTION_CONTRACT_KEY not in metadata:
            raise StartupError(f"{source} has no {LOCOMOTION_CONTRACT_KEY} metadata: not exported by dynpush from a"
                               " locomotion run")
        try:
            values = json.loads(metadata[LOCOMOTION_CONTRACT_KEY])
            missing = sorted(set(REQUIRED_FIELDS) - set(values))
            if missing:
                raise StartupError(f"{source}: {LOCOMOTION_CONTRACT_KEY} lacks {missing}; export the run again with"
                                   " this dynpush")
            return LocomotionContract(
                observation=tuple((str(t["name"]), float(t["scale"])) for t in values["observation"]),
                joint_names=tuple(str(n) for n in values["joint_names"]),
                default_joint_positions=tuple(float(v) for v in values["default_joint_positions"]),
                action_scale=float(values["action_scale"]),
                joint_lower=tuple(float(v) for v in values["joint_lower"]),
                joint_upper=tuple(float(v) for v in values["joint_upper"]),
                values=values,
            )
        except (ValueError, KeyError, TypeError) as error:  # JSON errors are ValueErrors
            raise StartupError(f"{source}: malformed {LOCOMOTION_CONTRACT_KEY} metadata ({error})") from error

    @staticmethod
    def read(path: str) -> LocomotionContract:
        """The contract of the ONNX file ``path``."""
        import onnxruntime as ort

        try:
            session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime raises its own exception types for unreadable models
            raise StartupError(f"locomotion.onnx: cannot load {path}: {error}") from error
        return LocomotionContract.from_metadata(session.get_modelmeta().custom_metadata_map, str(path))

    def section(self, path: str) -> OnnxLocomotionConfig:
        """The runtime's ``locomotion.onnx`` config section that runs this network from ``path``."""
        return OnnxLocomotionConfig(
            path=str(path),
            observation=[LocomotionTerm(name=name, scale=scale) for name, scale in self.observation],
            joint_names=list(self.joint_names),
            default_joint_positions=list(self.default_joint_positions),
            action_scale=self.action_scale,
        )

    def check(self, cfg: OnnxLocomotionConfig) -> None:
        """Raises :class:`StartupError` listing every field where ``cfg`` disagrees with this contract (if any)."""
        configured, trained = _comparable(cfg), _comparable(self.section(cfg.path))
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


def _comparable(section: OnnxLocomotionConfig) -> dict[str, object]:
    """The fields of a config section that a contract fixes, as plain lists and floats."""
    return {
        "observation": [(t.name, float(t.scale)) for t in section.observation],
        "joint_names": list(section.joint_names),
        "default_joint_positions": [float(v) for v in section.default_joint_positions],
        "action_scale": float(section.action_scale),
    }
