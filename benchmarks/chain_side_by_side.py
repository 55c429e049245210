"""Does the deployment chain lose the robot, or do the policies? The same episodes through the runtime and in simulation.

For each seed, ``dynpush sim2sim`` runs the push policy (and, by default, the shipped locomotion policy) in the
deployment runtime, lock-step, against the simulator, which records every step (``--record``). Then each of those
episodes runs again from its recorded start state with both policies inside the environment, as ``dynpush eval`` runs
them (``dynpush.policies.chain_replay``). Side by side: the outcome of every episode both ways, how far the base paths
drift apart, and, term by term, the runtime's observations against the kernels' of the same states. A fall or a
failure that happens only through the runtime is the chain's; one that happens both ways is the policies'.

A fall ends a sim-to-sim run (the runtime's safety layer latches STOPPED, as on the robot), so a seed may give fewer
episodes than asked for.

Writes ``side_by_side.json`` and ``side_by_side.png`` (base paths of every episode, both ways) into ``--out`` and
prints the JSON summary; exits 2 on a bad input (one line).

    python benchmarks/chain_side_by_side.py [--seeds 0 1] [--episodes 4] [--locomotion onnx|onboard]
        [--policy dynpush/shipped/policy.onnx] [--locomotion-policy F] [--out runs/chain_side_by_side] [--set env.F=V ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def side_by_side(policy: str, locomotion_policy: str | None, seed: int, episodes: int, overrides: list[str],
                 out: Path) -> dict:
    """One seed: the sim-to-sim run, its record's episodes in simulation, and their comparison."""
    from dynpush.policies.chain_record import read_record
    from dynpush.policies.chain_replay import compare_observations, path_divergence, replay_in_simulation, safety_clamps
    from dynpush.policies.onnx_policy import OnnxPolicy
    from dynpush.runtime.locomotion_contract import LocomotionContract
    from dynpush.runtime.sim2sim import SimToSimOptions, run_sim2sim
    from dynpush.runtime.tick_log import read_log

    record_path = out / f"seed{seed}.npz"
    report = run_sim2sim(SimToSimOptions(policy=policy, episodes=episodes, lockstep=True, seed=seed,
                                         overrides=overrides, log_dir=str(out / "logs"), record=str(record_path),
                                         locomotion_policy=locomotion_policy))
    record = read_record(record_path)
    log = read_log(report["runtime"]["log"])
    observations = compare_observations(record, log)
    clamps = safety_clamps(log, OnnxPolicy(policy).contract,
                           LocomotionContract.read(locomotion_policy) if locomotion_policy else None)
    simulated = replay_in_simulation(record, policy, locomotion_policy, log)
    rows = []
    for i, sim in enumerate(simulated):
        chain_base = record.episode_rows("base_pose", i)[:, :3]
        ended = i < len(report["episode_results"])
        chain = report["episode_results"][i] if ended else None
        rows.append({
            "seed": seed, "episode": i,
            "chain": ({k: chain[k] for k in ("success", "toppled", "fallen", "steps")} if ended else
                      {"stopped_by_runtime": report["runtime"].get("final_reason"), "steps": len(chain_base)}),
            "simulation": {k: sim[k] for k in ("success", "toppled", "fallen", "steps")},
            "base_paths": path_divergence(chain_base, sim["base_position"]),
            "_paths": (chain_base, sim["base_position"]),
        })
    return {"seed": seed, "runtime_final_state": report["runtime"].get("final_state"),
            "runtime_final_reason": report["runtime"].get("final_reason"), "observations": observations,
            "safety_clamped_share": clamps,
            "episodes": rows}


def outcome(row: dict) -> str:
    if "stopped_by_runtime" in row:
        return "stopped"
    return "success" if row["success"] else "toppled" if row["toppled"] else "fell" if row["fallen"] else "failed"


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(4, len(rows))
    lines = -(-len(rows) // columns)
    fig, axes = plt.subplots(lines, columns, figsize=(3.6 * columns, 3.6 * lines), squeeze=False)
    for ax, row in zip(axes.flat, rows):
        chain, sim = row["_paths"]
        ax.plot(chain[:, 0], chain[:, 1], "-", color="tab:blue", label="through the runtime")
        ax.plot(sim[:, 0], sim[:, 1], "--", color="tab:orange", label="in simulation")
        ax.plot(*chain[0, :2], "ko", markersize=4)
        ax.set_title(f"seed {row['seed']} episode {row['episode']}\nruntime: {outcome(row['chain'])},"
                     f" simulation: {outcome(row['simulation'])}", fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(rows):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="best")
    fig.suptitle("Base paths [m], the same episodes through the runtime (lock-step) and in simulation", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def summary(seeds: list[dict]) -> dict:
    rows = [row for seed in seeds for row in seed["episodes"]]
    both = [(outcome(r["chain"]), outcome(r["simulation"])) for r in rows]
    worst: dict[str, dict[str, float]] = {}
    for seed in seeds:
        for block in ("push_observation", "locomotion_observation"):
            for term, d in seed["observations"].get(block, {}).items():
                if d["max"] is not None:
                    key = f"{block}.{term}"
                    worst[key] = max(worst.get(key, 0.0), d["max"])
    return {"episodes": len(rows), "same_outcome": sum(a == b for a, b in both),
            "outcomes_runtime": {k: sum(a == k for a, _ in both) for k in sorted({a for a, _ in both})},
            "outcomes_simulation": {k: sum(b == k for _, b in both) for k in sorted({b for _, b in both})},
            "largest_observation_difference": worst}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--policy", default=None, help="push policy ONNX (default: the shipped one)")
    parser.add_argument("--locomotion", choices=("onnx", "onboard"), default="onnx")
    parser.add_argument("--locomotion-policy", default=None, help="locomotion ONNX (default: the shipped one)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--episodes", type=int, default=4, help="per seed (a fall ends a seed's run early)")
    parser.add_argument("--out", default="runs/chain_side_by_side")
    parser.add_argument("--set", nargs="*", default=[], metavar="env.FIELD=VALUE")
    args = parser.parse_args()

    from dynpush.errors import UserError
    from dynpush.shipped import shipped_file

    try:
        policy = str(Path(args.policy or shipped_file("policy.onnx")).resolve())
        locomotion = (None if args.locomotion == "onboard"
                      else str(Path(args.locomotion_policy or shipped_file("locomotion/locomotion.onnx")).resolve()))
        for path in (policy, locomotion):
            if path and not Path(path).is_file():
                raise UserError(f"--policy/--locomotion-policy: {path} does not exist")
        if args.episodes < 1:
            raise UserError(f"--episodes must be >= 1, got {args.episodes}")
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        seeds = []
        for seed in args.seeds:
            print(f"chain_side_by_side: seed {seed}, {args.episodes} episodes through the runtime, then in simulation",
                  file=sys.stderr, flush=True)
            seeds.append(side_by_side(policy, locomotion, seed, args.episodes, list(args.set), out))
    except UserError as error:
        print(f"chain_side_by_side: {error}", file=sys.stderr)
        return 2
    rows = [row for seed in seeds for row in seed["episodes"]]
    plot(rows, out / "side_by_side.png")
    for row in rows:
        row.pop("_paths")
    result = {"policy": policy, "locomotion_policy": locomotion, "overrides": args.set, "summary": summary(seeds),
              "seeds": seeds, "png": str(out / "side_by_side.png")}
    (out / "side_by_side.json").write_text(json.dumps(result, indent=1))
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
