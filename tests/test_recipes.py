"""Recipe files (``dynpush train --recipe``): overrides one per line, the shipped recipes equal to the commands that
trained the shipped policy, and one-line errors for a missing or malformed file."""

import json
import shlex
from pathlib import Path

import pytest

from dynpush.cli import main
from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS
from dynpush.policies.schedules import ConstraintCurriculumConfig
from dynpush.policies.train import TrainConfig
from dynpush.policies.overrides import apply_overrides, apply_recipe, read_recipe
from dynpush.sim.config import ConfigError

ROOT = Path(__file__).resolve().parent.parent
RECIPES = ROOT / "configs" / "recipes"


def config_of(overrides: list[str]) -> dict:
    return json.loads(json.dumps(apply_overrides(TrainConfig.preset_config("cpu"), overrides).to_dict()))


def test_a_recipe_is_its_lines_without_comments_in_order(tmp_path):
    recipe = tmp_path / "r.txt"
    recipe.write_text("# a comment\n\nppo.learning_rate=3e-4\n  iterations=10  \n# p_max_overrides={}\n"
                      "p_max_overrides={'collision': (0.1, 1.0)}\n")
    assert read_recipe(recipe) == ["ppo.learning_rate=3e-4", "iterations=10", "p_max_overrides={'collision': (0.1, 1.0)}"]


@pytest.mark.parametrize("text, message", [
    ("iterations=10\nppo.learning_rate 3e-4\n", r"r\.txt: line 2: expected field\.path=value, got 'ppo\.learning_rate 3e-4'"),
    ("iterations=10\nppo.learning_rat=3e-4\n", r"r\.txt: unknown config field 'ppo\.learning_rat'"),
])
def test_a_bad_recipe_names_the_file(tmp_path, text, message):
    recipe = tmp_path / "r.txt"
    recipe.write_text(text)
    with pytest.raises(ConfigError, match=message):
        apply_recipe(TrainConfig.preset_config("cpu"), recipe, [])


def renamed(override: str) -> str:
    """A recorded ``--set`` item with the field's path of today (the commands were run before fine_tune existed)."""
    path, value = override.split("=", 1)
    return f"{TrainConfig.MOVED_FIELDS.get(path, path)}={value}"


PREDATES_ADDED_FIELDS = [f"{path}={value}" for path, value in TrainConfig.ADDED_FIELDS.items()]
"""What a command recorded before the fields added since trained with, in today's fields."""


@pytest.mark.parametrize("recipe, command", [("shipped_imitation.txt", 0), ("shipped_finetune.txt", 1)])
def test_the_shipped_recipes_are_the_shipped_commands(recipe, command):
    argv = shlex.split(json.loads((ROOT / "dynpush" / "shipped" / "training.json").read_text())["commands"][command])
    recorded = [renamed(item) for item in argv[argv.index("--set") + 1 :]] + PREDATES_ADDED_FIELDS
    assert config_of(read_recipe(RECIPES / recipe)) == config_of(recorded)


def test_the_shipped_finetune_recipe_is_the_shipped_config():
    # The shipped run's config.json (flat fine-tuning fields), read as --resume reads it.
    recorded = TrainConfig.from_dict(json.loads((ROOT / "dynpush" / "shipped" / "training_config.json").read_text()))
    assert config_of(read_recipe(RECIPES / "shipped_finetune.txt")) == json.loads(json.dumps(recorded.to_dict()))


def test_the_long_run_recipe_is_the_long_runs_config():
    # The recorded config, with the fields added since it was written at their defaults (as --resume reads it).
    recorded = TrainConfig.from_dict(json.loads((ROOT / "campaigns" / "long1" / "config.json").read_text())).to_dict()
    recorded = json.loads(json.dumps(recorded))
    from_recipe = config_of(read_recipe(RECIPES / "long_run.txt"))
    recorded["network"]["hold_actor_normalizer"] = from_recipe["network"]["hold_actor_normalizer"]  # set at creation
    assert from_recipe == recorded


def test_set_applies_after_the_recipe(tmp_path, monkeypatch):
    recipe = tmp_path / "r.txt"
    recipe.write_text("iterations=10\nenv.num_envs=8\n")
    seen = {}
    monkeypatch.setattr("dynpush.policies.training.train", lambda cfg, run_dir, **kw: seen.update(cfg=cfg, run_dir=run_dir))
    assert main(["train", "--name", "r", "--runs", str(tmp_path), "--recipe", str(recipe), "--set", "iterations=3"]) == 0
    assert (seen["cfg"].iterations, seen["cfg"].env.num_envs) == (3, 8)


@pytest.mark.parametrize("command, argv, message", [
    ("train", ["--recipe", "missing.txt"], "recipe missing.txt not found"),
    ("train", ["--recipe", "missing.txt", "--resume"], "--recipe configures a new run"),
    ("imitate", ["--recipe", "missing.txt", "--resume"], "--recipe configures a new run"),
])
def test_recipe_errors_are_one_line(tmp_path, capsys, monkeypatch, command, argv, message):
    monkeypatch.chdir(tmp_path)
    assert main([command, "--name", "r", "--runs", str(tmp_path), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dynpush: ") and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "r").exists()


def test_the_curricula_recipe_is_the_long_run_with_every_curriculum_and_cat_from_zero():
    """The curricula recipe differs from the long run's in its curricula and CaT's p_max curriculum only: from a tenth of
    the paper's final values to them, with the curricula's level."""
    long_run = config_of(read_recipe(RECIPES / "long_run.txt"))
    curricula = config_of(read_recipe(RECIPES / "curricula_from_scratch.txt"))
    TrainConfig.from_dict(curricula).validate()
    changed = {key for key in curricula if curricula[key] != long_run[key]}
    assert changed == {"curriculum", "distance_curriculum", "mass_curriculum", "behind_starts", "p_max_overrides",
                       "p_max_follows_curricula"}
    assert all(curricula[key]["enabled"] for key in ("curriculum", "distance_curriculum", "mass_curriculum",
                                                     "behind_starts"))
    assert curricula["behind_starts"]["share"] == 1.0
    assert set(curricula["p_max_overrides"]) == {name for name, _ in CONSTRAINT_GROUPS}
    for name, (initial, final) in curricula["p_max_overrides"].items():  # a tenth of the paper's final values first
        assert final == ConstraintCurriculumConfig().p_max[name][1] and initial == pytest.approx(final / 10), name
    assert curricula["p_max_follows_curricula"] is True
    assert {(curricula[key]["promote_above"], curricula[key]["demote_below"]) for key in (
        "curriculum", "distance_curriculum", "mass_curriculum", "behind_starts")} == {(0.2, 0.05)}
