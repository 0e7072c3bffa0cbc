"""Scenario files: the TOML schema (terrain, sun, start, commands, navigation, sensors, pass criteria), validated on
load, and the catalogue under ``scenarios/``."""
