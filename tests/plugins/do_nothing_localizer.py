"""A global localiser that does nothing: it returns its prior as the fix, with the prior's covariance.

Kept as a plugin for the benchmark's own test: ``bench globalloc`` must fail it (every fix is the prior, 2-35 m
off: false fixes everywhere). ``rover-sim bench globalloc --localizer tests.plugins.do_nothing_localizer:DoNothing``.
"""

from __future__ import annotations

import numpy as np

from nav.globalloc import GlobalLocResult


class DoNothing:
    def localize(self, views, R_world_rover, prior_xy_yaw, prior_covariance, orbital):  # noqa: ANN001, ANN201
        return GlobalLocResult("ok", "", np.asarray(prior_xy_yaw, float).copy(), np.asarray(prior_covariance, float))
