"""Recipe validation: out-of-range values are pydantic ValidationErrors naming the field."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from terrains import (
    CraterSpec,
    Disc,
    ExplicitRockSpec,
    MaterialSpec,
    RippleSpec,
    RockSpec,
    RoughnessSpec,
    SlopeSpec,
    TerrainRecipe,
)


def _error_locs(err: ValidationError) -> list[str]:
    return [".".join(str(p) for p in e["loc"]) for e in err.errors()]


def test_defaults_are_valid_and_give_the_documented_grid() -> None:
    recipe = TerrainRecipe()
    assert recipe.grid_shape == (401, 401)
    assert recipe.cell_size_m == 0.05
    assert recipe.rocks.exclusion_zones == [Disc(0.0, 0.0, 1.5)]


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"slope": {"slope_deg": 60}}, "slope.slope_deg"),
        ({"cell_size_m": 0.001}, "cell_size_m"),
        ({"cell_size_m": 3.0}, "cell_size_m"),
        ({"size_m": (-5, 10)}, "size_m.0"),
        ({"roughness": {"rms_m": 0.8}}, "roughness.rms_m"),
        ({"roughness": {"octaves": 9}}, "roughness.octaves"),
        ({"roughness": {"hurst": 1.5}}, "roughness.hurst"),
        ({"craters": [{"diameter_m": 0.5}]}, "craters.0.diameter_m"),
        ({"craters": [{"depth_to_diameter": 0.5}]}, "craters.0.depth_to_diameter"),
        ({"rocks": {"cover_fraction": 0.7}}, "rocks.cover_fraction"),
        ({"rocks": {"max_height_m": 2.0}}, "rocks.max_height_m"),
        ({"material": {"kind": "ice"}}, "material.kind"),
        ({"material": {"bedrock_fraction": 1.2}}, "material.bedrock_fraction"),
        ({"ripples": {"sharpness": 2.0}}, "ripples.sharpness"),
    ],
)
def test_out_of_range_fields_are_rejected_with_their_name(kwargs: dict, field: str) -> None:
    with pytest.raises(ValidationError) as info:
        TerrainRecipe.model_validate(kwargs)
    assert field in _error_locs(info.value)


def test_slope_60_deg_is_rejected_directly() -> None:
    with pytest.raises(ValidationError) as info:
        SlopeSpec(slope_deg=60)
    assert "slope_deg" in str(info.value)


def test_unknown_keys_are_errors() -> None:
    with pytest.raises(ValidationError) as info:
        TerrainRecipe.model_validate({"slope": {"slope_degrees": 10}})
    assert "slope.slope_degrees" in _error_locs(info.value)


def test_cross_field_checks() -> None:
    with pytest.raises(ValidationError, match="min_height_m"):
        RockSpec(min_height_m=0.8, max_height_m=0.5)
    with pytest.raises(ValidationError, match="bedrock_fraction \\+ mixed_fraction"):
        MaterialSpec(kind="patches", bedrock_fraction=0.8, mixed_fraction=0.3)
    with pytest.raises(ValidationError, match="buried_fraction"):
        RockSpec(buried_fraction=(0.5, 0.2))
    with pytest.raises(ValidationError, match="radius_m > 0"):
        RockSpec(exclusion_zones=[(0.0, 0.0, -1.0)])


def test_explicit_rock_checks() -> None:
    wopmay = {"name": "Wopmay", "x_m": 2.0, "y_m": -1.0, "length_m": 1.5, "width_m": 0.9, "height_m": 0.6}
    assert TerrainRecipe(explicit_rocks=[wopmay]).explicit_rocks[0].name == "Wopmay"
    with pytest.raises(ValidationError, match="outside the patch"):
        TerrainRecipe(size_m=(10, 10), explicit_rocks=[{**wopmay, "x_m": 7.0}])
    with pytest.raises(ValidationError, match="duplicate rock name"):
        TerrainRecipe(explicit_rocks=[wopmay, wopmay])
    with pytest.raises(ValidationError, match="reserved"):
        ExplicitRockSpec(**{**wopmay, "name": "rock_0001"})
    with pytest.raises(ValidationError, match="round footprint"):
        ExplicitRockSpec(**{**wopmay, "shape": "hemispheroid"})


def test_grid_limits() -> None:
    with pytest.raises(ValidationError, match="larger cell_size_m"):
        TerrainRecipe(size_m=(2000, 2000), cell_size_m=0.01)
    with pytest.raises(ValidationError, match="at least 2 cells"):
        TerrainRecipe(size_m=(0.05, 10), cell_size_m=0.05)


def test_too_many_rocks_is_an_error_that_says_what_to_change() -> None:
    with pytest.raises(ValidationError, match="min_height_m"):
        TerrainRecipe(size_m=(500, 500), cell_size_m=0.5, rocks=RockSpec(cover_fraction=0.5, min_height_m=0.02))


def test_recipe_json_round_trip() -> None:
    recipe = TerrainRecipe(
        size_m=(12.0, 8.0),
        slope=SlopeSpec(slope_deg=17.0, azimuth_deg=30.0),
        roughness=RoughnessSpec(rms_m=0.03),
        ripples=RippleSpec(amplitude_m=0.15, wavelength_m=2.5),
        craters=[CraterSpec(center_xy_m=(-40.0, 0.0), diameter_m=130.0, depth_to_diameter=0.15)],
        rocks=RockSpec(exclusion_zones=[(1.0, 2.0, 3.0)]),
        material=MaterialSpec(kind="patches", outcrop_slope_deg=25.0),
    )
    again = TerrainRecipe.model_validate_json(recipe.model_dump_json())
    assert again == recipe
    assert isinstance(again.rocks.exclusion_zones[0], Disc)


def test_recipes_are_frozen() -> None:
    recipe = TerrainRecipe()
    with pytest.raises(ValidationError):
        recipe.cell_size_m = 0.1  # type: ignore[misc]
