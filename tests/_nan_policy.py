"""A policy that answers NaN: for the tests of what a non-finite duty does to a run."""

import numpy as np


class NanPolicy:
    """``mission_sim.contract.Policy`` that returns ``d_short = nan`` for every receiver."""

    name = "broken"

    def reset(self, n=1):
        pass

    def act(self, obs):
        return np.array([np.nan])
