"""A tiny scenario for command-line tests: 0.6 m on a 12 deg slope with a few small rocks and VO, seconds to run."""

TINY_TOML = """
name = "tiny"
seed = 3
commands = [{type = "drive", distance_m = 0.6}]
[terrain]
size_m = [8, 6]
cell_size_m = 0.05
slope = {slope_deg = 12, azimuth_deg = 0}
rocks = {cover_fraction = 0.05, min_height_m = 0.05, max_height_m = 0.12, exclusion_zones = [[-2, 0, 1.0]]}
[start]
x_m = -2.0
[nav]
vo = true
vo_step_m = 0.3
"""
