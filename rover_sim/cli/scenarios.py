"""`rover-sim scenarios`: the scenario catalogue, one line per scenario with its description's first sentence."""

from __future__ import annotations

import typer

from rover_sim.cli.status import fail
from rover_sim.errors import RoverSimError

ABBREVIATIONS = ("e.g.", "i.e.", "al.", "cf.", "vs.", "approx.", "fig.")  # a full stop that ends no sentence


def first_sentence(text: str) -> str:
    """The first sentence of ``text`` whole (whitespace collapsed): up to the first ``.``, ``!`` or ``?`` that is
    followed by a space or the end, outside brackets and not ending an abbreviation such as "et al."."""
    text = " ".join(text.split())
    depth = 0
    for i, ch in enumerate(text):
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth = max(depth - 1, 0)
        elif ch in ".!?" and depth == 0 and (i + 1 == len(text) or text[i + 1] == " "):
            if text[: i + 1].rsplit(" ", 1)[-1].lower() not in ABBREVIATIONS:
                return text[: i + 1]
    return text


def scenarios_cmd() -> None:
    """List the scenario catalogue: name, `fast` (in the CI subset) and the description's first sentence."""
    from rover_sim.scenario.loading import catalogue, load_scenario

    names = catalogue()
    if not names:
        from rover_sim.resources import scenarios_dir

        raise fail(f"no scenario files (*.toml) in {scenarios_dir()}")
    width = max((len(n) for n in names), default=0)
    bad = False
    for name in names:
        try:
            s = load_scenario(name)
        except RoverSimError as e:
            typer.echo(f"{name:<{width}}  ?     invalid: {e}")
            bad = True
            continue
        first = first_sentence(s.description)
        typer.echo(f"{name:<{width}}  {'fast' if s.fast else '-   '}  {first}")
    if bad:
        raise typer.Exit(code=2)
