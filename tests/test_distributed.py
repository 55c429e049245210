"""Two-process gloo training on the CPU (torch.distributed, as torchrun launches it)."""

import json

import torch
import torch.multiprocessing as mp

from train_helpers import free_tcp_port, join_as_rank


def _rank_main(rank: int, world_size: int, port: int, out_dir: str) -> None:
    join_as_rank(rank, world_size, port)
    from pathlib import Path

    from dynpush.policies.cat_ppo import CaTPPO
    from dynpush.policies.train import TrainConfig, apply_overrides, train

    snapshots = []
    original = CaTPPO.update

    def update(self):
        result = original(self)
        flat = torch.cat([p.detach().reshape(-1) for p in self.actor.parameters()])
        snapshots.append({"params": flat.tolist(), "c_max": self.c_max.tolist(),
                          "obs_mean": self.actor.obs_normalizer.mean.reshape(-1).tolist()})
        return result

    CaTPPO.update = update
    cfg = apply_overrides(TrainConfig.preset_config("cpu"), [
        "env.num_envs=16", "iterations=3", "num_steps_per_env=6", "save_interval=100",
        "network.actor_hidden=(16, 16)", "network.critic_hidden=(16, 16)"])
    runner = train(cfg, Path(out_dir) / "run")
    Path(out_dir, f"rank{rank}.json").write_text(json.dumps({
        "snapshots": snapshots, "num_envs": runner.env.num_envs, "seed": runner.env.cfg.seed,
        "group_destroyed": not torch.distributed.is_initialized()}))


def test_two_gloo_ranks_keep_identical_policies(tmp_path):
    mp.spawn(_rank_main, args=(2, free_tcp_port(), str(tmp_path)), nprocs=2, join=True)
    ranks = [json.loads((tmp_path / f"rank{r}.json").read_text()) for r in range(2)]
    assert [r["num_envs"] for r in ranks] == [8, 8]  # 16 worlds split over two shards
    assert all(r["group_destroyed"] for r in ranks), "train() ends the process group (gloo's threads stop before exit)"
    assert ranks[0]["seed"] != ranks[1]["seed"]  # each shard draws its own episodes
    assert len(ranks[0]["snapshots"]) == len(ranks[1]["snapshots"]) == 3
    for a, b in zip(ranks[0]["snapshots"], ranks[1]["snapshots"]):
        assert a["params"] == b["params"], "ranks diverged after an update"
        assert a["c_max"] == b["c_max"]
        assert a["obs_mean"] == b["obs_mean"]
    assert ranks[0]["snapshots"][0]["params"] != ranks[0]["snapshots"][-1]["params"]  # it did learn
    assert (tmp_path / "run" / "model_2.pt").exists() and (tmp_path / "run" / "config.json").exists()
