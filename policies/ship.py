"""``dynpush ship``: export a run's policy into the package with its evaluation and provenance.

One step, so the shipped files always belong together (``dynpush.shipped``): the checkpoint is
exported to ``policy.onnx``, evaluated with ``dynpush eval`` on the training distribution (4096
episodes by default, paper IV-A), the learning curve is drawn from ``progress.jsonl``, and
``training.json`` records the training command(s) from ``launches.jsonl``, the seed, the commit, the
checkpoint, the training wall-clock and world-steps (the DAgger rounds of a run started by ``dynpush
imitate`` included, and also listed on their own; a run started with ``--init-from`` counts the run it
started from), and the evaluation summary. A locomotion run (``dynpush train --task locomotion``) ships the same
way into ``dynpush/shipped/locomotion/``: ``locomotion.onnx``, its tracking evaluation and its provenance.
"""

from __future__ import annotations

import json
from pathlib import Path

from dynpush.errors import MissingFileError

from .checkpoint_file import read_checkpoint
from .export import resolve_checkpoint
from .onnx_policy import OnnxPolicy
from .progress import imitation_summary, plot_learning_curve, training_records, wall_clock_hours
from .tasks import load_run_config, task_of_run


def read_launches(run_dir: Path) -> list[dict]:
    """The ``dynpush imitate`` / ``dynpush train`` launches of a run (``launches.jsonl``), oldest first."""
    path = run_dir / "launches.jsonl"
    if not path.exists():
        raise MissingFileError(f"{path} not found: the run's training command is unknown (dynpush train writes it)")
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def provenance(run_dir: Path, checkpoint_path: Path) -> dict:
    """What trained ``run_dir``'s checkpoint: its commands, seed, iterations, world-steps and wall-clock (DAgger
    rounds included); a run started with ``--init-from`` adds the run it started from (``initialised_from``), whose
    commands come first and whose world-steps and hours are counted in."""
    cfg = load_run_config(run_dir)
    launches = read_launches(run_dir)
    iteration = int(read_checkpoint(checkpoint_path)["iter"])  # completed iterations
    trained = [r for r in training_records(run_dir) if r["iteration"] < iteration]
    imitation = imitation_summary(run_dir)
    record = {
        "run": run_dir.name,
        "commands": [launch["command"] for launch in launches],
        "launches": launches,
        "seed": cfg.env.seed,
        "checkpoint": checkpoint_path.name,
        "iterations": iteration,
        # CaT-PPO iterations, plus the DAgger rounds of a run started by dynpush imitate
        "world_steps": iteration * cfg.num_steps_per_env * cfg.env.num_envs + (imitation["world_steps"] if imitation else 0),
        "training_wall_clock_h": (float(wall_clock_hours(trained)[-1]) if trained else 0.0)
                                 + (imitation["wall_clock_h"] if imitation else 0.0),
        "imitation": imitation,
    }
    source = launches[0].get("init_from")
    if source is not None:
        upstream = onnx_provenance(Path(source)) if source.endswith(".onnx") else provenance(Path(source).parent, Path(source))
        record["initialised_from"] = upstream
        record["commands"] = upstream["commands"] + record["commands"]
        record["world_steps"] += upstream["world_steps"]
        record["training_wall_clock_h"] += upstream["training_wall_clock_h"]
    return record


def onnx_provenance(policy_path: Path) -> dict:
    """What trained an exported ``policy.onnx`` that a run started from: the ``training.json`` that ``dynpush ship``
    wrote beside it when it belongs to that file (same training config hash), else a record that says the
    file's history is unknown (no commands, world-steps or hours counted)."""
    record_path = policy_path.parent / "training.json"
    sha = OnnxPolicy(policy_path).contract.training_config_sha256
    if record_path.exists():
        record = json.loads(record_path.read_text())
        if record.get("training_config_sha256") == sha:
            return record
    return {"run": None, "policy": str(policy_path), "training_config_sha256": sha, "history": "unknown",
            "commands": [], "world_steps": 0, "training_wall_clock_h": 0.0}


def ship(run_dir: Path, out_dir: Path, checkpoint: str | None = None, episodes: int = 4096, seed: int = 0,
         locomotion_worlds: int = 256) -> dict:
    """Writes the shipped files of ``run_dir``'s checkpoint (default: the latest) into ``out_dir``; returns training.json.

    A push run's files are ``policy.onnx`` and its ``dynpush eval`` of ``episodes`` episodes; a locomotion run's
    ``locomotion.onnx`` and its tracking evaluation on ``locomotion_worlds`` worlds (``dynpush
    eval-locomotion``, locomotion_eval.json / .png)."""
    run_dir = Path(run_dir)
    checkpoint_path = resolve_checkpoint(run_dir, checkpoint)
    record = provenance(run_dir, checkpoint_path)
    out_dir.mkdir(parents=True, exist_ok=True)
    record |= task_of_run(run_dir).ship_files(run_dir, checkpoint_path, out_dir, episodes=episodes,
                                              worlds=locomotion_worlds, seed=seed)
    paper = record["evaluation"].get("paper")  # a push run's: its curve marks the paper's success rate
    # a push run started with --init-from: the DAgger rounds of the run it started from come first in its curve
    source = record["launches"][0].get("init_from") if paper else None
    paper_success = paper["success_rate"] if paper else None
    plot_learning_curve(run_dir, out_dir / "learning_curve.png", paper_success, record["iterations"],
                        imitation_run=Path(source).parent if source else None)
    # The config the export embedded: the run's config.json as read today (an older run's gets the sections and fields
    # added since, e.g. fine_tune), so that training_config.json equals the policy's training_config.
    (out_dir / "training_config.json").write_text(json.dumps(load_run_config(run_dir).to_dict(), indent=2))
    (out_dir / "training.json").write_text(json.dumps(record, indent=2))
    return record

