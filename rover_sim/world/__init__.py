"""The world: a scenario's terrain, physics, sensors and cameras as one object (``World``), its calibration, clock
and what it shows the rover (``Observation``)."""
