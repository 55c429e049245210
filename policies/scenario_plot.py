"""``scenario.png``: the figure of a scenario run (``scenarios.py``) from its ``scenario.json`` result.

Top: success rate [%] and face switches per successful goal of each object beside the paper's hardware values.
Bottom, one panel per object (world frame, m): the object's centroid path and the robot base's path of the first
run, the object's start outline and its goal outlines, numbered in sequence order.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .scenario_schema import Scenario


def plot_scenario(scenario: Scenario, result: dict, paths: np.ndarray, path: Path) -> None:
    """Success rate and face switches per object beside the paper's; the object paths of the first run.

    ``result``: :func:`~.scenarios.run_scenario`'s (``scenario.json``); ``paths`` (steps, objects, 2, 2): per step and
    object, the object centroid's and the robot base's (x, y) [m, world frame] in its first run, NaN once that run is
    over; ``path``: the PNG written.
    """
    from matplotlib.figure import Figure

    from .play import draw_outline

    count = len(scenario.objects)
    fig = Figure(figsize=(max(10, 3 * count), 8), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=(1, 1.1))
    ax_success, ax_switches = top.subplots(1, 2)
    names = [o.name for o in scenario.objects]
    x = np.arange(count)
    rows = [result["objects"][name] for name in names]
    for ax, key, label in ((ax_success, "success_rate", "success rate [%]"),
                           (ax_switches, "face_switches_per_goal", "face switches / successful goal")):
        ours = [np.nan if r[key] is None else r[key] for r in rows]  # no bar where undefined
        paper = [r["paper"].get(key, np.nan) for r in rows]
        ax.bar(x - 0.2, ours, 0.4, label="this policy")
        ax.bar(x + 0.2, paper, 0.4, label="paper (hardware)", color="tab:gray")
        ax.set_xticks(x, names, fontsize=8, rotation=20)
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    ax_success.set_ylim(0, 105)
    ax_switches.set_ylim(bottom=0)
    ax_success.set_title(f"{scenario.name}: {scenario.trials} runs per object")
    ax_switches.set_title("contact face switches (cuboids)")

    axes = np.atleast_1d(bottom.subplots(1, count))
    for index, (ax, obj) in enumerate(zip(axes, scenario.objects)):
        ax.plot(paths[:, index, 1, 0], paths[:, index, 1, 1], color="tab:blue", lw=0.8, label="robot base (run 0)")
        ax.plot(paths[:, index, 0, 0], paths[:, index, 0, 1], color="k", lw=1.2, label="object (run 0)")
        ax.plot(0.0, 0.0, "ko", ms=3)
        labels: dict[tuple[float, float], list[str]] = {}  # goals at one position share a label: "1,3"
        for k, (gx, gy, gyaw) in enumerate(obj.goal_poses()):
            draw_outline(ax, obj.shape, obj.dims, (gx, gy), gyaw, color="tab:green", ls="-", lw=1)
            labels.setdefault((round(gx, 3), round(gy, 3)), []).append(str(k + 1))
        for (gx, gy), numbers in labels.items():
            ax.annotate(",".join(numbers), (gx, gy), color="tab:green", fontsize=8, ha="center", va="center")
        draw_outline(ax, obj.shape, obj.dims, (0.0, 0.0), math.radians(obj.start_yaw_deg), color="gray", ls="--", lw=1)
        # Frame the object's path and the goals; a robot that wanders off leaves the picture.
        points = np.vstack([paths[:, index, 0][~np.isnan(paths[:, index, 0, 0])], [(0.0, 0.0)],
                            [pose[:2] for pose in obj.goal_poses()]])
        low, high = points.min(axis=0) - 1.0, points.max(axis=0) + 1.0
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_aspect("equal", adjustable="box")
        outcomes = result["objects"][obj.name]["outcomes"]
        ax.set_title(f"{obj.name}\n" + ", ".join(f"{v} {k}" for k, v in outcomes.items() if v), fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=7)
    fig.savefig(path, dpi=100)
