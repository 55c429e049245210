"""The push policy shipped with dynpush, its evaluation and its provenance.

``dynpush demo`` runs ``policy.onnx`` through the deployment runtime against the simulator. The files
beside it are written together by ``dynpush ship RUN`` (``dynpush.policies.ship``):

- ``policy.onnx``: the exported actor, contract in its metadata;
- ``training.json``: the exact ``dynpush train`` command(s), seed, commit, checkpoint, training
  wall-clock and world-steps, and the evaluation summary;
- ``training_config.json``: the run's full training config;
- ``eval.json`` / ``eval.png``: ``dynpush eval`` on the training distribution (paper Tables I/II);
- ``learning_curve.png``: success and rewards against training wall-clock hours.

``locomotion/`` holds the legged robot's locomotion policy the same way (``dynpush ship`` of a ``dynpush train
--task locomotion`` run): ``locomotion.onnx``, ``locomotion_eval.json`` / ``.png`` (command tracking),
``training.json``, ``training_config.json`` and ``learning_curve.png``. ``dynpush sim2sim --locomotion onnx`` and
``dynpush demo --locomotion onnx`` run it when no other locomotion ONNX is given.

Only the standard library here: the deployment runtime imports this module.
"""

from __future__ import annotations

import json
from pathlib import Path

from dynpush.errors import MissingFileError

SHIPPED_DIR = Path(__file__).resolve().parent
LOCOMOTION_DIR = SHIPPED_DIR / "locomotion"


def shipped_file(name: str) -> Path:
    """The shipped file ``name`` (e.g. ``policy.onnx``, ``locomotion/locomotion.onnx``); a MissingFileError naming it
    when absent."""
    path = SHIPPED_DIR / name
    if not path.is_file():
        raise MissingFileError(f"{path} is missing: this dynpush installation ships no {name}"
                               " (write it with dynpush ship RUN)")
    return path


def training_record(folder: str = "") -> dict:
    """The contents of ``training.json`` (of the push policy; ``folder="locomotion"``: of the locomotion policy)."""
    return json.loads(shipped_file(f"{folder}/training.json" if folder else "training.json").read_text())
