"""A run folder's life across launches: --hours, the --procs launcher's signals, evaluations during training, the
curve of several launches, kept checkpoints, and what a launch refuses before it writes anything."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.multiprocessing as mp

from dynpush.cli import main
from dynpush.policies.checkpoint_file import CheckpointError
from dynpush.policies.train import PPOConfig, apply_overrides, train
from dynpush.sim.config import ConfigError

from train_helpers import TINY, free_tcp_port, join_as_rank, tiny

NO_TIME = 1e-9  # hours: spent before the first iteration ends, so a launch runs exactly one iteration


def assert_same_training(a, b) -> None:
    """Same weights, normalisers and CaT c_max in two runners."""
    for model in ("actor", "critic"):
        theirs = getattr(b.alg, model).state_dict()
        for name, value in getattr(a.alg, model).state_dict().items():
            assert torch.equal(value, theirs[name]), f"{model}.{name}"
    assert torch.equal(a.alg.c_max, b.alg.c_max)


def lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


# ---------------------------------------------------------------------------------------------- --hours
def test_hours_stop_then_resume_equals_the_uninterrupted_run(tmp_path, capsys):
    straight = train(tiny(4), tmp_path / "straight")

    run = tmp_path / "split"
    first = train(tiny(4), run, hours=NO_TIME)
    assert first.current_learning_iteration == 0 and "time budget: stopped before iteration 1" in capsys.readouterr().out
    assert torch.load(run / "model_0.pt", weights_only=False)["iter"] == 1  # the runner's save: iteration 1 is next
    second = train(tiny(4), run, resume=True, hours=NO_TIME)  # --hours with --resume
    assert second.current_learning_iteration == 1
    torch.manual_seed(123)  # the checkpoint's RNG state must win over whatever the new process has
    resumed = train(tiny(4), run, resume=True)
    assert resumed.current_learning_iteration == straight.current_learning_iteration == 3
    assert_same_training(straight, resumed)
    assert [launch["resume"] for launch in lines(run / "launches.jsonl")] == [False, True, True]


def test_time_budget_counts_the_evaluation_due_before_the_next_iteration():
    from dynpush.policies.runner import TimeBudget

    budget = TimeBudget.of_hours(1.0, started=1000.0)
    budget.iteration_s, budget.evaluation_s = 100.0, 50.0
    assert budget.next_iteration_fits(now=1000.0 + 3500.0, evaluating=False)
    assert not budget.next_iteration_fits(now=1000.0 + 3500.0, evaluating=True)
    assert not budget.next_iteration_fits(now=1000.0 + 3501.0, evaluating=False)


def _rank_with_own_budget(rank: int, world_size: int, port: int, out_dir: str) -> None:
    join_as_rank(rank, world_size, port)
    cfg = apply_overrides(tiny(5), ["env.num_envs=16"])
    runner = train(cfg, Path(out_dir) / "run", hours=NO_TIME if rank == 0 else 1000.0)  # rank 0's clock decides
    Path(out_dir, f"rank{rank}.json").write_text(json.dumps({"iteration": runner.current_learning_iteration}))


def test_all_ranks_stop_at_the_boundary_rank_0_chooses(tmp_path):
    mp.spawn(_rank_with_own_budget, args=(2, free_tcp_port(), str(tmp_path)), nprocs=2, join=True)
    assert [json.loads((tmp_path / f"rank{r}.json").read_text())["iteration"] for r in range(2)] == [0, 0]
    assert sorted(p.name for p in (tmp_path / "run").glob("model_*.pt")) == ["model_0.pt"]
    assert torch.load(tmp_path / "run" / "model_0.pt", weights_only=False)["iter"] == 1


def _rank_of_a_split_run(rank: int, world_size: int, port: int, out_dir: str, name: str, hours: float | None) -> None:
    join_as_rank(rank, world_size, port)
    run = Path(out_dir) / name
    runner = train(tiny(4, "env.num_envs=16"), run, resume=(run / "config.json").exists(), hours=hours)
    torch.save({"actor": runner.alg.actor.state_dict(), "c_max": runner.alg.c_max, "env": runner.env.state_dict()},
               Path(out_dir) / f"{name}_rank{rank}.pt")


def two_ranks(tmp_path: Path, name: str, hours: float | None = None) -> None:
    mp.spawn(_rank_of_a_split_run, args=(2, free_tcp_port(), str(tmp_path), name, hours), nprocs=2, join=True)


def test_two_processes_resume_their_own_episodes_and_equal_the_uninterrupted_run(tmp_path):
    two_ranks(tmp_path, "straight")  # a checkpoint after every iteration, written at the next boundary
    two_ranks(tmp_path, "split", hours=NO_TIME)  # stops after iteration 0
    saved = torch.load(tmp_path / "split" / "model_0.pt", weights_only=False)
    assert saved["iter"] == 1 and len(saved["infos"]["other_processes"]) == 1  # rank 1's episodes and RNG too
    two_ranks(tmp_path, "split")
    # Resumed from a periodic checkpoint of the uninterrupted run, its iterations 2 and 3 again.
    shutil.copytree(tmp_path / "straight", tmp_path / "periodic")
    for later in ("model_2.pt", "model_3.pt"):
        (tmp_path / "periodic" / later).unlink()
    assert torch.load(tmp_path / "periodic" / "model_1.pt", weights_only=False)["iter"] == 2
    two_ranks(tmp_path, "periodic")
    for run in ("split", "periodic"):
        for rank in range(2):
            straight = torch.load(tmp_path / f"straight_rank{rank}.pt", weights_only=False)
            resumed = torch.load(tmp_path / f"{run}_rank{rank}.pt", weights_only=False)
            for name, value in straight["actor"].items():
                assert torch.equal(value, resumed["actor"][name]), f"{run}, rank {rank}: actor.{name}"
            assert torch.equal(straight["c_max"], resumed["c_max"])
            for name, value in straight["env"].items():
                assert np.array_equal(value, resumed["env"][name]), f"{run}, rank {rank}: environment state {name}"


# ---------------------------------------------------------------------------------------------- launcher signals
def process_tree(root: int) -> set[int]:
    """``root`` and every process below it (from /proc)."""
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        parents[int(stat.parent.name)] = int(fields[1])
    tree, grown = {root}, True
    while grown:
        below = {pid for pid, parent in parents.items() if parent in tree} - tree
        tree |= below
        grown = bool(below)
    return tree


def running(pid: int) -> bool:
    """Whether ``pid`` is a live process (a zombie left for a parent that never reaps it is not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_sigterm_to_the_procs_launcher_stops_every_rank_with_a_checkpoint(tmp_path):
    run = tmp_path / "run"
    command = [sys.executable, "-m", "dynpush", "train", "--procs", "2", "--runs", str(tmp_path), "--name", "run",
               "--set", *TINY, "env.num_envs=16", "iterations=100000", "save_interval=100000"]
    launcher = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    tree = {launcher.pid}
    try:
        deadline = time.monotonic() + 180.0
        while not ((run / "progress.jsonl").exists() and len((run / "progress.jsonl").read_text().splitlines()) >= 2):
            assert launcher.poll() is None and time.monotonic() < deadline, "the 2-process run did not start"
            time.sleep(0.2)
        tree = process_tree(launcher.pid)
        assert len(tree) >= 4  # launcher, torchrun, two ranks
        launcher.send_signal(signal.SIGTERM)
        assert launcher.wait(timeout=120) != 0
        time.sleep(1.0)
        assert not [pid for pid in tree if running(pid)], "processes of the run outlived the launcher"
    finally:
        for pid in tree:
            if running(pid):
                os.kill(pid, signal.SIGKILL)
    saved = max(int(p.stem.split("_")[1]) for p in run.glob("model_*.pt"))
    assert saved >= 2  # the interrupted iteration's boundary, not only the first iteration's save
    assert torch.load(run / f"model_{saved}.pt", weights_only=False)["iter"] == saved


# ---------------------------------------------------------------------------------------------- evaluations
def test_evaluations_during_training_leave_the_training_unchanged(tmp_path):
    short = ["env.episode_length_s=0.3", "eval_episodes=3"]
    torch.manual_seed(0)
    plain = train(tiny(4, *short), tmp_path / "plain")
    torch.manual_seed(0)
    evaluated = train(tiny(4, *short, "eval_interval=2"), tmp_path / "evaluated")
    assert_same_training(plain, evaluated)

    records = lines(tmp_path / "evaluated" / "evaluations.jsonl")
    assert [r["iteration"] for r in records] == [0, 2]
    assert [r["world_steps"] for r in records] == [0, 2 * 6 * 8] and [r["episodes"] for r in records] == [3, 3]
    assert records[0]["training_hours"] == 0.0 < records[1]["training_hours"]
    assert set(records[1]["constraint_violation_percent"]) >= {"collision", "object_balance"}
    assert all(0.0 <= r["success_rate"] <= 100.0 and 0.0 <= r["toppled_rate"] <= 100.0 for r in records)
    for r in records:  # how the episodes ended: success and toppled as above, the failures split by goal error
        outcome = r["outcome_percent"]
        assert (outcome["success"], outcome["toppled"]) == (r["success_rate"], r["toppled_rate"])
        assert 0.0 <= sum(outcome.values()) <= 100.0 + 1e-9
    progress = lines(tmp_path / "evaluated" / "progress.jsonl")
    assert [r["eval_s"] > 0.0 for r in progress] == [True, False, True, False]  # kept out of the rollout time


def test_every_evaluation_starts_the_same_episodes_on_the_papers_task(tmp_path):
    from dynpush.policies.actor import build_actor
    from dynpush.policies.training_eval import PeriodicEvaluation

    cfg = tiny(1, "env.episode_length_s=0.2", "eval_episodes=2", "eval_interval=1", "env.sampling.goal_radius=(0.0, 0.1)")
    evaluation = PeriodicEvaluation(cfg, tmp_path)
    assert evaluation.env.cfg.sampling.goal_radius == (0.0, 2.0)  # not the run's narrowed goals
    ends = []
    actor = build_actor(cfg)
    for _ in range(2):
        evaluation(0, actor)
        ends.append(evaluation.env.get_observations()["policy"].clone())
    assert torch.equal(ends[0], ends[1])  # the same episodes and a deterministic actor: the same ends


def test_curve_draws_evaluations_against_world_steps_and_hours_of_all_launches(tmp_path):
    from dynpush.policies.progress import read_evaluations, read_progress, wall_clock_hours

    run = tmp_path / "run"
    run.mkdir()
    rows = [  # an evaluation of 10 s before iteration 2, then a second launch after a 2-hour pause
        {"iteration": 0, "time": 100.0, "collect_s": 1.0, "learn_s": 1.0, "eval_s": 0.0, "/episode/success": 0.0},
        {"iteration": 1, "time": 103.0, "collect_s": 1.0, "learn_s": 1.0, "eval_s": 0.0, "/episode/success": 0.5},
        {"iteration": 2, "time": 116.0, "collect_s": 1.0, "learn_s": 1.0, "eval_s": 10.0, "/episode/success": 0.5},
        {"iteration": 3, "time": 7316.0, "collect_s": 1.0, "learn_s": 1.0, "eval_s": 0.0, "/episode/success": 1.0},
    ]
    (run / "progress.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    np.testing.assert_allclose(wall_clock_hours(read_progress(run)) * 3600.0, [2.0, 5.0, 18.0, 20.0])
    evaluation = {"episodes": 4, "constraint_violation_percent": {"collision": 1.0, "object_balance": 3.0}}
    evaluations = [{"iteration": 0, "world_steps": 0, "training_hours": 0.0, "success_rate": 0.0, "toppled_rate": 0.0},
                   {"iteration": 2, "world_steps": 96, "training_hours": 5.0 / 3600, "success_rate": 10.0, "toppled_rate": 0.0},
                   {"iteration": 2, "world_steps": 96, "training_hours": 5.0 / 3600, "success_rate": 25.0, "toppled_rate": 5.0,
                    "outcome_percent": {"at_goal_rotation_off": 40.0}}]  # recorded from this one on
    (run / "evaluations.jsonl").write_text("".join(json.dumps({**e, **evaluation}) + "\n" for e in evaluations))
    assert [e["success_rate"] for e in read_evaluations(run)] == [0.0, 25.0]  # a repeated evaluation keeps its last
    assert main(["curve", str(run), "--out", str(tmp_path / "curve.png")]) == 0
    assert (tmp_path / "curve.png").read_bytes()[:4] == b"\x89PNG"


# ---------------------------------------------------------------------------------------------- checkpoints
def test_checkpoints_are_written_whole_and_only_the_newest_kept(tmp_path, monkeypatch):
    from dynpush.policies import run_folder

    for k in range(4):
        run_folder.save_checkpoint({"iter": k + 1}, tmp_path / f"model_{k}.pt", keep=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model_2.pt", "model_3.pt"]

    def interrupted_save(state, f):
        f.write(b"half a checkpoint")
        raise KeyboardInterrupt

    monkeypatch.setattr(run_folder.torch, "save", interrupted_save)
    with pytest.raises(KeyboardInterrupt):
        run_folder.save_checkpoint({"iter": 4}, tmp_path / "model_3.pt", keep=2)
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model_2.pt", "model_3.pt"]  # no temporary file left
    assert torch.load(tmp_path / "model_3.pt", weights_only=False) == {"iter": 4}


def test_keep_checkpoints_prunes_a_training_runs_folder(tmp_path):
    train(tiny(3, "keep_checkpoints=2"), tmp_path / "run")
    assert sorted(p.name for p in (tmp_path / "run").glob("model_*.pt")) == ["model_1.pt", "model_2.pt"]


# ---------------------------------------------------------------------------------------------- refusals
def folder_files(run: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}


def test_a_new_run_refuses_a_folder_that_holds_a_run(tmp_path, capsys):
    args = ["train", "--runs", str(tmp_path), "--name", "run", "--set", *TINY, "iterations=1"]
    assert main(args) == 0
    before = folder_files(tmp_path / "run")
    capsys.readouterr()
    assert main(args) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and str(tmp_path / "run") in error and "--resume" in error
    assert folder_files(tmp_path / "run") == before
    assert main([*args[:5], "--procs", "2", *args[5:]]) == 2  # the launcher refuses before torchrun starts
    assert "--resume" in capsys.readouterr().err


def test_resume_falls_back_to_the_newest_readable_checkpoint(tmp_path, capsys):
    run = tmp_path / "run"
    train(tiny(2), run)
    newest = run / "model_1.pt"
    newest.write_bytes(newest.read_bytes()[:100])  # truncated, e.g. by a full disk
    resumed = train(tiny(2), run, resume=True)
    out = capsys.readouterr().out
    assert "--resume: skipped unreadable model_1.pt" in out and "resuming from model_0.pt" in out
    assert resumed.current_learning_iteration == 1  # model_0.pt's next iteration, run again

    for checkpoint in run.glob("model_*.pt"):
        checkpoint.write_bytes(b"not a checkpoint")
    before = folder_files(run)
    with pytest.raises(CheckpointError, match="no readable checkpoint in .*model_1.pt.*model_0.pt"):
        train(tiny(2), run, resume=True)
    assert folder_files(run) == before  # neither config.json nor launches.jsonl written


def test_a_new_run_writes_nothing_before_its_init_from_checkpoint_is_read(tmp_path):
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="bad.pt"):
        train(tiny(1), tmp_path / "run", init_from=tmp_path / "bad.pt")
    assert not (tmp_path / "run").exists()


def test_a_checkpoint_whose_critic_reads_other_inputs_is_refused_by_name(tmp_path):
    """A run started before the critic read ``object_at_goal`` (62 inputs) does not seed a new run's critic (63): one
    error naming the tensor and the settings that must match, and the new folder is not created."""
    train(tiny(1, "env.critic_reads_object_at_goal=False"), tmp_path / "old")
    with pytest.raises(CheckpointError, match=r"critic obs_normalizer._mean has shape \(1, 62\), this run's \(1, 63\).*"
                                              r"env.critic_reads_object_at_goal"):
        train(tiny(1), tmp_path / "new", init_from=tmp_path / "old" / "model_0.pt")
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("field, value", [
    ("learning_rate", -1.0), ("learning_rate", 0.0), ("learning_rate", 2.0), ("gamma", 0.0), ("gamma", 1.5),
    ("lam", -0.1), ("clip_param", 0.0), ("num_learning_epochs", 0), ("num_mini_batches", 0), ("entropy_coef", -0.01),
    ("desired_kl", 0.0), ("schedule", "cosine")])
def test_ppo_settings_out_of_range_are_refused(field, value):
    with pytest.raises(ConfigError, match=f"ppo.{field}"):
        PPOConfig(**{field: value}).validate()


def test_an_invalid_ppo_setting_fails_before_the_run_folder_exists(tmp_path, capsys):
    assert main(["train", "--runs", str(tmp_path), "--name", "run", "--set", *TINY, "ppo.learning_rate=-1"]) == 2
    assert "ppo.learning_rate must lie in (0, 1], got -1.0" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
