"""``eval.png``: the figure of ``dynpush eval`` from its ``eval.json`` result (Tables I and II beside the paper's,
time to success, where the episodes end, success by the rotation the goal asks and by where the robot starts)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .episodes import FirstEpisodes


def plot_eval(result: dict, time_to_success: np.ndarray, final: tuple[np.ndarray, np.ndarray], episodes: FirstEpisodes,
              path: Path) -> None:
    """Table II beside the paper's values, Table I (success/toppled) beside the paper's, time to success, where the
    episodes end (``final``: distance [m] and rotation error [deg] to the goal), success by the rotation asked and by
    where the robot starts."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    fig = Figure(figsize=(28, 4.8), layout="constrained")
    ax_constraints, ax_rates, ax_time, ax_final, ax_asked, ax_side = fig.subplots(
        1, 6, width_ratios=(2.2, 1.2, 1.2, 1.2, 1.0, 1.0))
    names = list(result["constraint_violation_percent"])
    x = np.arange(len(names))
    ours = [result["constraint_violation_percent"][n] for n in names]
    paper = [result["paper"]["constraint_violation_percent"][n] for n in names]
    for offset, values, label, color in ((-0.2, ours, "this policy", None), (0.2, paper, "paper (Table II)", "tab:gray")):
        drawn = ax_constraints.bar(x + offset, values, 0.4, label=label, color=color)
        ax_constraints.bar_label(drawn, fmt="%.3g", fontsize=6)
    ax_constraints.set_xticks(x, [n.replace("_", "\n") for n in names], fontsize=8)
    ax_constraints.set_yscale("symlog", linthresh=0.01)
    ax_constraints.set_ylabel("time violated [% of episode]")
    ax_constraints.set_title("Constraint violation (Table II)")
    ax_constraints.legend()

    groups = ["success", "toppled"]
    bars = [(f"this policy ({result['episodes']})", result, None)]
    bars += [(f"{shape} ({stats['episodes']})", stats, None) for shape, stats in result["by_shape"].items()]
    bars += [("paper: " + result["paper"]["table_I_row"], result["paper"], "tab:gray")]
    width = 0.8 / len(bars)
    x = np.arange(len(groups))
    for index, (label, source, color) in enumerate(bars):
        values = [np.nan if source[k] is None else source[k] for k in ("success_rate", "toppled_rate")]
        drawn = ax_rates.bar(x - 0.4 + width * (index + 0.5), values, width, label=label, color=color)
        ax_rates.bar_label(drawn, fmt="%.1f", fontsize=7)
    ax_rates.set_xticks(x, groups)
    ax_rates.set_ylim(0, 105)
    ax_rates.set_ylabel("rate [%]")
    ax_rates.set_title("Success and toppled objects (Table I)")
    ax_rates.legend(fontsize=7, loc="upper right")

    if time_to_success.size:
        ax_time.hist(time_to_success, bins=30, color="tab:green")
        ax_time.axvline(float(np.median(time_to_success)), color="k", ls="--", label="median")
        ax_time.legend()
    else:
        ax_time.text(0.5, 0.5, "no successful episode", ha="center", va="center", transform=ax_time.transAxes)
    ax_time.set_xlabel("time to success [s]")
    ax_time.set_ylabel("episodes")
    ax_time.set_title("Time to success")

    distance, angle = final
    success_distance = result["config"]["env"]["rewards"]["success_distance"]
    success_angle = result["config"]["env"]["rewards"]["success_angle_deg"]
    fell, failed = episodes.fell, episodes.failed
    for mask, label, color in ((episodes.success, "success", "tab:green"), (failed, "failed", "tab:red"),
                               (episodes.toppled, "toppled", "k"), (fell, "robot fell", "tab:purple")):
        ax_final.scatter(np.maximum(distance[mask], 1e-3), angle[mask], s=4, alpha=0.5, color=color,
                         label=f"{label} ({int(mask.sum())})")
    ax_final.add_patch(Rectangle((1e-3, 0.0), success_distance - 1e-3, success_angle, fill=False, ls="--", color="k"))
    ax_final.set_xscale("log")
    ax_final.set_xlabel("object-goal distance at the end [m]")
    ax_final.set_ylabel("rotation error at the end [deg]")
    ax_final.set_title("Where episodes end (box: success tolerance)")
    ax_final.legend(fontsize=7, markerscale=3)

    for ax, key, xlabel, title in (
            (ax_asked, "success_by_goal_rotation_deg", "rotation the goal asks [deg]", "Success by goal rotation"),
            (ax_side, "success_by_start_side_deg", "robot start, from behind the object [deg]", "Success by start side")):
        bins = result["goal_error"][key]
        labels = [f"{b['from']:.0f}-{min(b['to'], 180.0):.0f}" for b in bins]
        drawn = ax.bar(labels, [np.nan if b["success_rate"] is None else b["success_rate"] for b in bins], color="tab:green")
        ax.bar_label(drawn, labels=[f"{b['episodes']}" for b in bins], fontsize=7)
        ax.set_ylim(0, 105)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("success [%] (bar label: episodes)")
        ax.set_title(title)
    noise = "on" if result["config"]["env"]["noise"]["enabled"] else "off"
    fig.suptitle(f"{result['policy']}: {result['episodes']} episodes of {result['config']['env']['episode_length_s']:g} s,"
                 f" observation noise {noise}")
    fig.savefig(path, dpi=110)
