"""``dynpush replay LOG``: re-runs the networks on the observations of a tick log.

Every tick whose policy ran (finite logged actions) is evaluated again by the push policy (the one
in the log's config, or another file to compare an export against a run); with a locomotion ONNX,
its logged inputs likewise. The report gives the largest absolute deviation and where it occurred.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .locomotion_layout import NUM_LEG_JOINTS
from .contract import INPUT_NAME, OUTPUT_NAME
from .observation import NUM_ACTIONS, POLICY_OBSERVATION_SIZE
from .policy import OnnxModel
from .tick_log import TickLog, TickLogError, read_log


def _deviation(model: OnnxModel, log: TickLog, inputs: str, outputs: str) -> dict:
    x, y = log.column(inputs), log.column(outputs)
    rows = np.flatnonzero(np.isfinite(x).all(axis=1) & np.isfinite(y).all(axis=1))
    worst, worst_tick = 0.0, None
    ticks = log.column("tick")[:, 0]
    for row in rows:
        model.input[0] = x[row]
        deviation = float(np.max(np.abs(model.run() - y[row])))
        if deviation > worst or worst_tick is None:
            worst, worst_tick = deviation, int(ticks[row])
    return {"policy": str(model.path), "compared_ticks": int(rows.size), "max_abs_deviation": worst,
            "worst_tick": worst_tick}


def _logged(log: TickLog, log_path: str | Path, *keys: str) -> object:
    """``meta["config"][keys[0]][keys[1]]...`` of the log's header; TickLogError naming the field if absent."""
    value: object = log.meta
    for key in ("config", *keys):
        if not isinstance(value, dict) or key not in value:
            raise TickLogError(f"{log_path}: the tick log's header lacks {'.'.join(keys) or 'the runtime config'}"
                               " (not written by dynpush run or sim2sim)")
        value = value[key]
    return value


def replay(log_path: str | Path, policy_path: str | Path | None = None) -> dict:
    """The deviation report of the module docstring, as a JSON-able dict."""
    log = read_log(log_path)
    push = OnnxModel(policy_path or _logged(log, log_path, "push_policy", "path"), INPUT_NAME, POLICY_OBSERVATION_SIZE,
                     OUTPUT_NAME, NUM_ACTIONS, "push_policy")
    report = {"log": str(log_path), "records": log.records, "partial_bytes": log.partial_bytes,
              "push_policy": _deviation(push, log, "obs", "actions")}
    if "locomotion_obs" in log.columns:
        onnx = _logged(log, log_path, "locomotion", "onnx")
        model = OnnxModel(onnx["path"], onnx["input_name"], log.column("locomotion_obs").shape[1], onnx["output_name"],
                          NUM_LEG_JOINTS, "locomotion.onnx")
        report["locomotion"] = _deviation(model, log, "locomotion_obs", "locomotion_actions")
    return report
