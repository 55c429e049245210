"""Reading a training checkpoint (``model_K.pt``, ``imitation.pt``, ``imitation_data.pt``) without running code from it.

A ``.pt`` file is a pickle, and a full unpickling builds whatever the file names: a crafted file given to
``--init-from`` or ``dynpush export`` could call ``os.system``. Every checkpoint is read with ``weights_only=True``,
which builds tensors, plain containers and numbers, plus exactly the globals of what dynpush itself saves besides
them (:data:`SAFE_GLOBALS`: the numeric numpy arrays of the environment state). Anything else is refused with a
:class:`CheckpointError` naming what the file would have imported.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import torch

from dynpush.errors import UserError

# Numpy pickles an array as _reconstruct(ndarray, shape, dtype) plus its state, and a dtype as dtype(code) plus the
# state of its class (numpy.dtypes.Float32DType...): these for the numeric types warp arrays copy into, nothing that
# holds Python objects. _reconstruct is taken from an array because numpy 2 moved its module (numpy.core -> _core).
NUMERIC_TYPES = (np.bool_, np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint16, np.uint32, np.uint64,
                 np.float16, np.float32, np.float64)
SAFE_GLOBALS = [np.zeros(0).__reduce__()[0], np.ndarray, np.dtype, *(type(np.dtype(t)) for t in NUMERIC_TYPES)]


class CheckpointError(UserError, RuntimeError):
    """A checkpoint that is missing, unreadable, or holds more than dynpush saves; the message names the file."""


def read_checkpoint(path: str | Path, map_location: str | None = "cpu") -> dict:
    """The dict ``torch.save`` wrote to ``path``, its tensors on ``map_location`` (None: where they were saved)."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist")
    try:
        with torch.serialization.safe_globals(SAFE_GLOBALS):
            loaded = torch.load(path, weights_only=True, map_location=map_location)
    except pickle.UnpicklingError:  # the weights-only unpickler met bytes or objects it must not build
        raise CheckpointError(f"checkpoint {path} refused: {_refusal(path)}") from None
    except Exception as error:  # a truncated or foreign file: zip, pickle and torch's readers each fail their own way
        raise CheckpointError(f"cannot read checkpoint {path}: {type(error).__name__}: "
                              f"{str(error).splitlines()[0] if str(error) else 'unreadable'}") from error
    if not isinstance(loaded, dict):
        raise CheckpointError(f"checkpoint {path} holds a {type(loaded).__name__}, not the dict dynpush saves")
    return loaded


def _refusal(path: Path) -> str:
    """Why the weights-only unpickler refused ``path``: what it would have imported, where torch can list that."""
    allowed = {f"{g.__module__}.{g.__qualname__}" for g in SAFE_GLOBALS}
    try:
        names = [n for n in torch.serialization.get_unsafe_globals_in_checkpoint(path) if n not in allowed]
    except (ValueError, RuntimeError):  # not a zip checkpoint (a bare pickle or other bytes): torch cannot list it
        names = []
    if names:
        return (f"it would import {', '.join(names)}, and a dynpush checkpoint holds only tensors, numeric numpy arrays"
                " and plain values (anything else could run code)")
    return "it is no pickle of tensors, numeric numpy arrays and plain values (corrupt, foreign, or crafted to run code)"
