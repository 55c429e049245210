"""ONNX networks on one CPU thread, and the start-up checks of the push policy against the config.

Every session runs with ``intra_op_num_threads = inter_op_num_threads = 1``, sequential execution
and no spinning (``session.intra_op.allow_spinning = 0``), so the runtime occupies one core and
sleeps between ticks. Inputs and outputs are preallocated float32 arrays bound once (IOBinding):
a tick writes into :attr:`OnnxModel.input` and reads :attr:`OnnxModel.output`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import onnxruntime as ort

from .actions import ACTION_LAYOUT, BASE_COMMAND_NAMES
from .config import RuntimeConfig
from .contract import INPUT_NAME, OUTPUT_NAME, ContractError, PolicyContract
from .errors import StartupError
from .observation import NUM_ACTIONS, POLICY_OBSERVATION_SIZE


def session_options() -> ort.SessionOptions:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    options.add_session_config_entry("session.inter_op.allow_spinning", "0")
    return options


def _check_io(what: str, kind: str, args: list, name: str, size: int) -> None:
    """One float tensor ``name`` of shape [1 (or symbolic), size] among ``args``."""
    found = {a.name: a for a in args}
    if name not in found:
        raise StartupError(f"{what}: the ONNX {kind} must be named {name!r}, found {sorted(found)}")
    arg = found[name]
    shape = list(arg.shape)
    batch_ok = len(shape) == 2 and (shape[0] == 1 or not isinstance(shape[0], int))
    if not batch_ok or shape[1] != size or arg.type != "tensor(float)":
        raise StartupError(f"{what}: ONNX {kind} {name!r} must be float32 [1, {size}], got {arg.type} {shape}")


class OnnxModel:
    """One network with a single float32 input ``[1, input_size]`` and output ``[1, output_size]``."""

    def __init__(self, path: str | Path, input_name: str, input_size: int, output_name: str, output_size: int,
                 what: str):
        path = Path(path)
        if not path.is_file():
            raise StartupError(f"{what}: ONNX file {path} does not exist")
        try:
            self.session = ort.InferenceSession(str(path), session_options(), providers=["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime raises its own exception types for unreadable models
            raise StartupError(f"{what}: cannot load {path}: {error}") from error
        _check_io(what, "input", self.session.get_inputs(), input_name, input_size)
        if len(self.session.get_inputs()) != 1:
            raise StartupError(f"{what}: the ONNX model must have exactly one input, got "
                               f"{[a.name for a in self.session.get_inputs()]}")
        _check_io(what, "output", self.session.get_outputs(), output_name, output_size)
        self.path = path
        self.metadata: dict[str, str] = dict(self.session.get_modelmeta().custom_metadata_map)
        self.input = np.zeros((1, input_size), dtype=np.float32)
        self.output = np.zeros((1, output_size), dtype=np.float32)
        self._binding = self.session.io_binding()
        self._binding.bind_input(input_name, "cpu", 0, np.float32, list(self.input.shape), self.input.ctypes.data)
        self._binding.bind_output(output_name, "cpu", 0, np.float32, list(self.output.shape), self.output.ctypes.data)

    def run(self) -> np.ndarray:
        """Evaluates the network on :attr:`input`; returns :attr:`output` [0] (a view, overwritten next run)."""
        self.session.run_with_iobinding(self._binding)
        return self.output[0]


def check_contract(contract: PolicyContract, cfg: RuntimeConfig) -> None:
    """Raises :class:`StartupError` listing every mismatch between the policy's contract and the config."""
    problems = []
    layout = [(str(n), int(s)) for n, s in contract.action_layout]
    if layout != list(ACTION_LAYOUT):
        problems.append(f"action_layout {layout} differs from this runtime's {list(ACTION_LAYOUT)}")
    if list(contract.base_command_names) != list(BASE_COMMAND_NAMES):
        problems.append(f"base_command_names {contract.base_command_names} differ from {list(BASE_COMMAND_NAMES)}")
    if list(contract.arm_joint_names) != list(cfg.robot.arm_joint_names):
        problems.append(f"arm_joint_names {contract.arm_joint_names} differ from robot.arm_joint_names"
                        f" {cfg.robot.arm_joint_names} (names and order must match)")
    if not math.isclose(contract.control_period_s, cfg.control_period_s, rel_tol=1e-6):
        problems.append(f"control_period_s {contract.control_period_s} s differs from rates.control_hz"
                        f" {cfg.rates.control_hz} (period {cfg.control_period_s} s)")
    s = cfg.safety
    for field, own, lower, upper in (
        ("safety.arm_joint", (s.arm_joint_lower, s.arm_joint_upper), contract.arm_joint_lower, contract.arm_joint_upper),
        ("safety.base_command", (s.base_command_lower, s.base_command_upper), contract.base_command_lower,
         contract.base_command_upper),
    ):
        if own[0] and (np.less(own[0], lower).any() or np.greater(own[1], upper).any()):
            problems.append(f"{field}_lower/_upper {own[0]} / {own[1]} must lie within the policy's {lower} / {upper}")
    if problems:
        raise StartupError(f"push policy {cfg.push_policy.path} does not match the runtime config: " + "; ".join(problems))


def load_push_policy(cfg: RuntimeConfig) -> tuple[OnnxModel, PolicyContract]:
    """The push policy (``obs`` [1, 54] -> ``actions`` [1, 11]) and its contract, checked against ``cfg``."""
    model = OnnxModel(cfg.push_policy.path, INPUT_NAME, POLICY_OBSERVATION_SIZE, OUTPUT_NAME, NUM_ACTIONS, "push_policy")
    try:
        contract = PolicyContract.from_metadata(model.metadata)
    except ContractError as error:
        raise StartupError(f"push_policy {cfg.push_policy.path}: {error}") from error
    check_contract(contract, cfg)
    return model, contract
