"""Config files and ``--set`` overrides: a config dataclass from a ``config.json``, recipe files (``--recipe``) and
``dotted.field=value`` overrides, each checked against the dataclass's fields and types (a ConfigError names the
field)."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path
from typing import TypeVar

from dynpush.errors import MissingFileError
from dynpush.sim.config import ConfigError

T = TypeVar("T")  # a config dataclass


def config_from_dict(cls: type[T], data: dict) -> T:
    """The config dataclass ``cls`` from a dict (a config.json): unknown fields are a ConfigError, nested dicts
    become their field's dataclass, lists become tuples where the default is a tuple; missing fields keep their
    defaults."""
    kwargs = {}
    names = {f.name: f for f in dataclasses.fields(cls)}
    for key, value in data.items():
        if key not in names:
            raise ConfigError(f"unknown config field {cls.__name__}.{key}; allowed: {sorted(names)}")
        default = getattr(cls(), key)
        if dataclasses.is_dataclass(default):
            value = config_from_dict(type(default), value)
        elif isinstance(default, tuple):
            value = tuple(value)
        kwargs[key] = value
    return cls(**kwargs)


def read_recipe(path: Path) -> list[str]:
    """The ``field.path=value`` overrides of a recipe file (``dynpush train --recipe``), in file order.

    One override per line, written as on the command line but without shell quoting; blank lines and lines that start
    with ``#`` are skipped. A missing file is a MissingFileError, a line without ``=`` a ConfigError naming the file
    and the line.
    """
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise MissingFileError(f"recipe {path} not found") from None
    except (OSError, UnicodeDecodeError) as error:
        raise ConfigError(f"is not readable text: {error}") from error
    overrides = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if "=" not in line:
            raise ConfigError(f"line {number}: expected field.path=value, got {line!r}")
        overrides.append(line)
    return overrides


def apply_recipe(cfg: T, recipe: Path | None, overrides: list[str]) -> T:
    """``cfg`` with the overrides of the recipe file ``recipe`` (if any), then ``overrides``; an invalid field of the
    recipe is a ConfigError that names the file."""
    if recipe is not None:
        try:
            cfg = apply_overrides(cfg, read_recipe(recipe))
        except ConfigError as error:
            raise ConfigError(f"recipe {recipe}: {error}") from None
    return apply_overrides(cfg, overrides)


def apply_overrides(cfg: T, overrides: list[str]) -> T:
    """Applies ``dotted.field=value`` overrides to a config dataclass (values parsed as Python literals, else strings).

    A field that moved into a section (the config class's ``MOVED_FIELDS``, old name -> new path, e.g.
    ``critic_warmup_iterations`` -> ``fine_tune.critic_warmup_iterations``) is a ConfigError naming its new path."""
    moved = getattr(cfg, "MOVED_FIELDS", {})
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override must look like field.path=value, got {item!r}")
        path, text = item.split("=", 1)
        if path in moved:
            raise ConfigError(f"{path} is now {moved[path]}: set {moved[path]}={text}")
        target = cfg
        keys = path.split(".")
        for key in keys[:-1]:
            if not hasattr(target, key) or not dataclasses.is_dataclass(getattr(target, key)):
                raise ConfigError(f"unknown config section {path!r}")
            target = getattr(target, key)
        leaf = keys[-1]
        if not dataclasses.is_dataclass(target) or leaf not in {f.name for f in dataclasses.fields(target)}:
            raise ConfigError(f"unknown config field {path!r}")
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            value = text
        current = getattr(target, leaf)
        expected = f"of type {type(current).__name__}"
        allowed = [type(current).__name__]
        if current is None or value is None:  # an optional field, e.g. ``float | None``: its annotation's types
            annotation = str(next(f.type for f in dataclasses.fields(target) if f.name == leaf))
            allowed = [name.strip() for name in annotation.split("|")]
            expected = annotation if current is None else expected
        if "float" in allowed and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(current, tuple) and isinstance(value, list):
            value = tuple(value)
        if ("None" if value is None else type(value).__name__) not in allowed:
            raise ConfigError(f"{path} must be {expected}, got {text!r}")
        if isinstance(current, tuple) and current:
            value = tuple_like(path, current, value, text)
        setattr(target, leaf, value)
    return cfg


def tuple_like(path: str, current: tuple, value: tuple, text: str) -> tuple:
    """``value`` with the element type of the default ``current`` (ints become floats in a tuple of floats); a
    ConfigError naming ``path`` when an element has another type."""
    kind = type(current[0])
    if kind is float:
        value = tuple(float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value)
    if not all(type(v) is kind for v in value):
        raise ConfigError(f"{path} must be a tuple of {kind.__name__}, got {text!r}")
    return value
