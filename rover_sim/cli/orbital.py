"""``rover-sim orbital`` (a site's orbital products) and ``rover-sim bench globalloc``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rover_sim.cli.outdir import outputs_or_exit
from rover_sim.cli.status import ExitStatus, exit_with, guarded


def orbital_cmd(
    scenario: Annotated[str, typer.Argument(help="Scenario name (see `rover-sim scenarios`) or a TOML path.")],
    out: Annotated[Path, typer.Option("--out", help="Output directory for the products.")],
    seed: Annotated[int | None, typer.Option("--seed", help="Replace the scenario's seed.")] = None,
    set_: Annotated[list[str] | None, typer.Option("--set", help="Override a scenario field: a.b=v.")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace a non-empty --out.")] = False,
) -> None:
    """Orbital products of SCENARIO's site: orthoimage (0.25 m, 16-bit PNG + .pgw), DEM (1 m, float32 TIFF +
    .tfw), orbital.json (frame, sun, error model with sources); a streamed site: tiles along the route."""
    outputs_or_exit(("--out", out, "dir"))
    with guarded():
        from rover_sim.cli.outdir import prepare_out_dir
        from rover_sim.orbital.files import spec_metadata, write_products
        from rover_sim.orbital.products import make_products, site_boxes
        from rover_sim.scenario.loading import load_scenario

        sc = load_scenario(scenario, overrides=set_ or [], seed=seed)
        prepare_out_dir(out, overwrite)
        boxes = site_boxes(sc)
        tiles, regs = [], []
        for k, box in enumerate(boxes):
            omap, reg = make_products(sc, box)
            tiles.append(("" if len(boxes) == 1 else f"_{k:03d}", omap))
            regs.append(reg)
            typer.echo(f"tile {k + 1}/{len(boxes)}: {omap.image.shape[1]} x {omap.image.shape[0]} px", err=True)
        meta = {
            "scenario": sc.name,
            "seed": sc.seed,
            "frame": "site frame of the scenario (x east, y north, z up, metres); north-up rasters",
            "image_units": "14-bit counts of relative radiance (sky + Lambertian sun, the simulator's photometry)",
            "dem_units": "metres, heights of the ground with rocks",
            "orbital": spec_metadata(sc.orbital),
            "sources": "rover_sim/orbital/spec.py",
            "registration_drawn": {
                "offset_xy_m": list(regs[0].offset_xy_m),
                "rotation_rad": regs[0].rotation_rad,
                "note": "truth, for evaluation only: a localiser must not read it",
            },  # fmt: skip
        }
        for path in write_products(out, tiles, meta):
            typer.echo(str(path))


def bench_globalloc_cmd(
    json: Annotated[Path | None, typer.Option("--json", help="Write the results as JSON to this path.")] = None,
    localizer: Annotated[
        list[str] | None,
        typer.Option(
            "--localizer",
            help="A global localiser to run beside the built-in: 'pkg.module:Class' or an "
            "entry point in 'rover_sim.plugins' (nav.protocols.GlobalLocalizer). Repeatable.",
        ),
    ] = None,  # fmt: skip
    seeds: Annotated[
        str | None, typer.Option("--seeds", help="Seeds as 'A-B' or 'A,B,C' (default: published 100-107).")
    ] = None,
    terrain: Annotated[list[str] | None, typer.Option("--terrain", help="Only these terrain types.")] = None,
    stops: Annotated[int, typer.Option("--stops", min=1, max=50, help="Stops per seed.")] = 5,
    cache: Annotated[Path, typer.Option("--cache", help="Panorama cache directory.")] = Path("runs/globalloc_cache"),
    junit: Annotated[Path | None, typer.Option("--junit", help="Write JUnit XML (one case per localiser).")] = None,
) -> None:
    """Global localisation against orbital products over rocky plains, a crater rim, a dune field and a
    featureless plain (flight profile): per-terrain fixes, refusals, false fixes, errors and compute."""
    outputs_or_exit(("--json", json, "file"), ("--junit", junit, "file"), ("--cache", cache, "dir"))
    with guarded():
        from rover_sim.bench.globalloc import bench_globalloc
        from rover_sim.bench.globalloc_sites import TERRAINS
        from rover_sim.errors import ConfigError

        seed_list = parse_seeds(seeds) if seeds else None
        for t in terrain or []:
            if t not in TERRAINS:
                raise ConfigError("--terrain", t, f"unknown terrain; one of {', '.join(TERRAINS)}")
        result = bench_globalloc(str(json) if json else None, localizer, seed_list, terrain, stops, cache)
    if junit:
        from rover_sim.cli.status import finish
        from rover_sim.io.junit import case

        cases = [case(name, "bench.globalloc", not [r for r in result["reasons"] if r.startswith(f"{name}: ")],
                      "; ".join(r for r in result["reasons"] if r.startswith(f"{name}: ")))
                 for name in result["localizers"]]  # fmt: skip
        finish(str(junit), "bench globalloc", cases)
    exit_with(ExitStatus.OK if result["passed"] else ExitStatus.FAILED)


def parse_seeds(text: str) -> list[int]:
    from rover_sim.errors import ConfigError

    try:
        if "-" in text:
            a, b = (int(v) for v in text.split("-", 1))
            out = list(range(a, b + 1))
        else:
            out = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ConfigError("--seeds", text, "expected 'A-B' or 'A,B,C' (non-negative integers)") from None
    if not out or min(out) < 0:
        raise ConfigError("--seeds", text, "expected 'A-B' or 'A,B,C' (non-negative integers)")
    return out
