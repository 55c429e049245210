"""ONNX files as the simulator and the tools read them: load with one-line errors, metadata, the input and
output check, and an onnxruntime session that runs all worlds of an environment in one call.

Used by the legged push environment (its frozen locomotion network) and by ``policies/onnx_policy.py`` (the push
policy); ``onnx`` and ``onnxruntime`` only, no torch.
"""

from __future__ import annotations

import copy
from pathlib import Path

import onnx
import onnxruntime

from dynpush.errors import CorruptFileError, MissingFileError
from dynpush.runtime.contract import ContractError

BATCH_DIM = "batch"  # symbolic batch dimension of a relaxed in-memory copy (batched_session)


def load_onnx(path: Path) -> onnx.ModelProto:
    """The ONNX model in ``path``; a MissingFileError or CorruptFileError naming the file otherwise."""
    if not Path(path).is_file():
        raise MissingFileError(f"ONNX file {path} not found")
    try:
        return onnx.load(str(path))
    except Exception as error:  # protobuf's DecodeError, or onnx's own errors, for a file that is no model
        raise CorruptFileError(f"{path} is not an ONNX model: {' '.join(str(error).split())}") from error


def read_metadata(model: onnx.ModelProto) -> dict[str, str]:
    """The ``metadata_props`` of an ONNX model as a dict."""
    return {prop.key: prop.value for prop in model.metadata_props}


def check_io(model: onnx.ModelProto, input_name: str, input_size: int, output_name: str, output_size: int,
             what: str) -> None:
    """Raises :class:`ContractError` unless ``model`` maps ``input_name`` [batch, input_size] to ``output_name``
    [batch, output_size]."""
    inputs = {v.name: v for v in model.graph.input}
    outputs = {v.name: v for v in model.graph.output}
    if input_name not in inputs or output_name not in outputs:
        raise ContractError(f"{what}: graph must have input {input_name!r} and output {output_name!r},"
                            f" has {sorted(inputs)} -> {sorted(outputs)}")
    for value, size in ((inputs[input_name], input_size), (outputs[output_name], output_size)):
        dims = [d.dim_value if d.HasField("dim_value") else d.dim_param for d in value.type.tensor_type.shape.dim]
        if len(dims) != 2 or dims[1] != size:
            raise ContractError(f"{what}: {value.name!r} has shape {dims}, expected [batch, {size}]")


def single_thread_options() -> onnxruntime.SessionOptions:
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    return options


def batched_session(model: onnx.ModelProto, input_name: str, input_size: int, output_name: str,
                    output_size: int, what: str) -> onnxruntime.InferenceSession:
    """An onnxruntime session of ``model`` (checked with :func:`check_io`) whose batch dimension is relaxed to a
    symbolic one in an in-memory copy (same graph and weights), so that all worlds run in one call."""
    check_io(model, input_name, input_size, output_name, output_size, what)
    model = copy.deepcopy(model)
    for value in (*model.graph.input, *model.graph.output):
        if value.name in (input_name, output_name):
            value.type.tensor_type.shape.dim[0].dim_param = BATCH_DIM
    del model.graph.value_info[:]  # shape hints of intermediates carry the fixed batch size
    return onnxruntime.InferenceSession(model.SerializeToString(), single_thread_options(), providers=["CPUExecutionProvider"])
