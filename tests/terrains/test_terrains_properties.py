"""Property test: every in-range recipe synthesises a finite, consistent terrain."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from terrains import Material, TerrainRecipe, synthesize


def _f(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def recipes(draw: st.DrawFn) -> TerrainRecipe:
    ripples = draw(
        st.none()
        | st.fixed_dictionaries(
            {
                "amplitude_m": _f(0, 2),
                "wavelength_m": _f(0.06, 100),
                "azimuth_deg": _f(-360, 360),
                "sharpness": _f(0, 1),
                "sinuosity": _f(0, 1),
            }
        )
    )
    crater = st.fixed_dictionaries(
        {
            "center_xy_m": st.tuples(_f(-50, 50), _f(-50, 50)),
            "diameter_m": _f(1, 2000),
            "depth_to_diameter": _f(0.05, 0.3),
            "rim_height_frac": _f(0, 0.1),
            "rim_width_frac": _f(0.01, 0.5),
            "floor_flatness": _f(0, 0.8),
        }
    )
    min_h = draw(_f(0.05, 1.5))
    lo_bf = draw(_f(0, 0.8))
    bed = draw(_f(0, 1))
    data = {
        "size_m": (draw(_f(1, 8)), draw(_f(1, 8))),
        "cell_size_m": draw(_f(0.05, 0.3)),
        "base_height_m": draw(_f(-100, 100)),
        "slope": {"slope_deg": draw(_f(0, 45)), "azimuth_deg": draw(_f(-360, 360))},
        "roughness": {
            "rms_m": draw(_f(0, 0.5)),
            "correlation_length_m": draw(_f(0.01, 1000)),
            "octaves": draw(st.integers(1, 8)),
            "hurst": draw(_f(0, 1)),
        },
        "ripples": ripples,
        "craters": draw(st.lists(crater, max_size=2)),
        "rocks": {
            "cover_fraction": draw(_f(0, 0.5)),
            "min_height_m": min_h,
            "max_height_m": draw(_f(min_h, 1.5)),
            "buried_fraction": (lo_bf, draw(_f(lo_bf, 0.8))),
            "shapes": draw(
                st.lists(
                    st.sampled_from(["hemispheroid", "semi_ellipsoid", "cone", "tetrahedron"]),
                    min_size=1,
                    max_size=4,
                )
            ),
            "exclusion_zones": draw(st.lists(st.tuples(_f(-5, 5), _f(-5, 5), _f(0.1, 3)), max_size=2)),
        },
        "material": {
            "kind": draw(st.sampled_from(["sand", "bedrock", "mixed", "patches"])),
            "bedrock_fraction": bed,
            "mixed_fraction": draw(_f(0, 1 - bed)),
            "patch_scale_m": draw(_f(0.1, 100)),
            "outcrop_slope_deg": draw(st.none() | _f(5, 60)),
        },
    }
    return TerrainRecipe.model_validate(data)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(recipe=recipes(), seed=st.integers(0, 2**32 - 1))
def test_in_range_recipes_give_finite_consistent_terrains(recipe: TerrainRecipe, seed: int) -> None:
    t = synthesize(recipe, seed)
    assert t.heights_m.shape == recipe.grid_shape
    assert np.all(np.isfinite(t.heights_m))
    assert set(np.unique(t.materials).tolist()) <= {int(m) for m in Material}
    for rock in t.rocks:
        assert abs(rock.x_m) <= t.half_x_m and abs(rock.y_m) <= t.half_y_m
        assert np.isfinite([rock.z_base_m, rock.buried_m, rock.height_m]).all()
        assert rock.height_m <= max(recipe.rocks.max_height_m, 3.0)
    if t.rocks:
        cx = np.array([r.x_m for r in t.rocks])
        cy = np.array([r.y_m for r in t.rocks])
        assert np.all(t.height_with_rocks_at(cx, cy) >= t.height_at(cx, cy))
