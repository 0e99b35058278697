"""Config on the command line: an option for every field (``--clip-epsilon 0.1``, ``--no-anneal-lr``), made from the
field's type, default and meaning, and ``train_argv``, which writes a Config back as ``minippo train``'s words.

The command line (cli.py) reads these words and a sweep (sweep.py) writes them, so they live here, below both: the
sweep names each run by the ``minippo train`` command that makes it alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools

from minippo.config import Config, field_types

FLAGS = {"env_id": "ENV", "total_steps": "--steps"}  # the fields whose option is not --field-name
METAVARS = {int: "N", float: "X", float | None: "X", str: "WORD"}
NAMED = ("env_id", "total_steps", "seed")  # the fields train_argv always writes, the run's name


def flag(name: str) -> str:
    """The option that sets the Config field ``name``: --clip-epsilon for clip_epsilon."""
    return FLAGS.get(name, "--" + name.replace("_", "-"))


def add_config_options(parser, skip=("env_id", "total_steps")) -> None:
    """An option for every Config field (but ``skip``), made from the field's type, default and meaning; true/false
    fields get --name and --no-name. Each sets ``args.set_<field>``, None when not given."""
    group = parser.add_argument_group(
        "settings", "every field of minippo.Config (minippo/config.py); --config KEY=VALUE sets them too"
    )
    kinds = field_types()
    for field in dataclasses.fields(Config):
        if field.name in skip:
            continue
        kind, words = kinds[field.name], field.metadata["choices"]
        shown = ",".join(map(str, field.default)) if isinstance(field.default, tuple) else field.default
        shown = "none: off" if shown is None else str(shown).lower() if kind is bool else shown
        options = dict(dest=f"set_{field.name}", default=None, help=f"{field.metadata['help']} (default: {shown})")
        if kind is bool:
            options["action"] = argparse.BooleanOptionalAction
        else:
            options["type"] = functools.partial(Config.parse_value, field.name)
            options["metavar"] = "|".join(words) if words else METAVARS.get(kind, "N,N")
        group.add_argument(flag(field.name), **options)


def train_argv(config: Config, out) -> list[str]:
    """The words after ``minippo train`` that train ``config`` into the folder ``out``: ENV, --steps, --seed and --out,
    then the option of every other field whose value is not its default, in the order of the fields. The command
    line's parser reads them back into ``config`` (``cli.train_config``)."""
    argv = [config.env_id, "--steps", str(config.total_steps), "--seed", str(config.seed), "--out", str(out)]
    for field in dataclasses.fields(Config):
        value = getattr(config, field.name)
        if field.name not in NAMED and value != field.default:
            argv += option(field.name, value)
    return argv


def option(name: str, value) -> list[str]:
    """The words that set the Config field ``name`` to ``value``: --lr 0.001, --no-anneal-lr, --hidden-sizes 32,32."""
    if isinstance(value, bool):
        return [flag(name) if value else "--no-" + flag(name)[2:]]
    return [flag(name), word(value)]


def word(value) -> str:
    """A Config value as ``Config.parse_value`` reads it: 0.001, 32,32 for a tuple, none for None."""
    if isinstance(value, tuple):
        return ",".join(str(v) for v in value)
    return "none" if value is None else str(value)
