"""Orbital products of a scenario's site: a HiRISE-class orthoimage and DEM in the site frame (``rover-sim orbital``).

:mod:`rover_sim.orbital.spec` is the scenario's ``[orbital]`` table (error model and its sources),
:mod:`rover_sim.orbital.products` makes the products from the site's terrain, :mod:`rover_sim.orbital.files` writes
and reads them (PNG / TIFF + world files + JSON metadata).
"""
