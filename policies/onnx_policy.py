"""An exported push policy (``policy.onnx``, written by :mod:`dynpush.policies.export`) run by onnxruntime.

Input ``obs`` [B, 54] float32, the un-normalised actor observation (layout
``dynpush.runtime.observation.POLICY_OBSERVATION_LAYOUT``); output ``actions`` [B, 11] float32, the deterministic
mean before the environment's clip to ``+-action_clip``. The file's ``metadata_props`` hold its
:class:`~dynpush.runtime.contract.PolicyContract`. Running a policy needs neither torch nor rsl_rl.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime

from dynpush.runtime.contract import INPUT_NAME, OUTPUT_NAME, ContractError, PolicyContract
from dynpush.runtime.observation import NUM_ACTIONS, POLICY_OBSERVATION_SIZE
from dynpush.sim.onnx_session import batched_session, check_io, load_onnx, read_metadata, single_thread_options


class OnnxPolicy:
    """A ``policy.onnx`` executed by onnxruntime, checked against the contract on load and on every call.

    With ``batched=True`` the batch dimension of ``obs`` and ``actions`` is relaxed to a symbolic one in
    an in-memory copy (same graph and weights), so that all worlds of an environment run in one call.
    """

    def __init__(self, path: Path, batched: bool = False):
        self.path = Path(path)
        model = load_onnx(self.path)
        try:
            self.contract = PolicyContract.from_metadata(read_metadata(model))
        except ContractError as error:
            raise ContractError(f"{self.path}: {error}") from None
        self.batch_size: int | None = None if batched else 1
        if batched:
            self.session = batched_session(model, INPUT_NAME, POLICY_OBSERVATION_SIZE, OUTPUT_NAME, NUM_ACTIONS, str(self.path))
        else:
            check_io(model, INPUT_NAME, POLICY_OBSERVATION_SIZE, OUTPUT_NAME, NUM_ACTIONS, str(self.path))
            self.session = onnxruntime.InferenceSession(model.SerializeToString(), single_thread_options(),
                                                        providers=["CPUExecutionProvider"])

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Actions [B, 11] (float32, unclipped mean) for observations ``obs`` [B, 54] (B = 1 unless batched)."""
        obs = np.asarray(obs)
        expected = f"[{self.batch_size or 'B'}, {POLICY_OBSERVATION_SIZE}]"
        if obs.ndim != 2 or obs.shape[1] != POLICY_OBSERVATION_SIZE or (self.batch_size and obs.shape[0] != self.batch_size):
            raise ValueError(f"policy input {INPUT_NAME!r} must have shape {expected} (float32), got {list(obs.shape)}")
        if obs.dtype != np.float32:
            raise ValueError(f"policy input {INPUT_NAME!r} must be float32, got {obs.dtype}")
        return self.session.run([OUTPUT_NAME], {INPUT_NAME: obs})[0]
