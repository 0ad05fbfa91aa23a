"""wpt_receiver: the WPT link with an SBAR receiver, as modelled in the paper.

Depends on nothing else of dronewpt. Main entry points:

* :class:`LinkParams` / :data:`TABLE_I` - parameters (Table I)
* :mod:`.envelope` - envelope model (eq. 3-8), exact ZOH stepping, steady states, G22
* :mod:`.sbar` - duty mapping f(d_short) (eq. 9) and its inverse
* :mod:`.inverse_controller` - the proposed controller (Fig. 5)
* :mod:`.references`, :mod:`.metrics`, :mod:`.paper` - Table II / Fig. 6 reproduction
* :mod:`.switching` - switching-level (instantaneous, event-exact) model of eq. 1 and the SBAR;
  importing it registers ``paper.MODELS["switching"]``
"""

from .envelope import EnvelopeLink, coefficients, g22, simulate, state_matrices, steady_state, zoh_discretise
from .inverse_controller import InverseModelController, LowPassFilter
from .metrics import TransitionMetrics, transition_metrics
from .params import TABLE_I, LinkParams
from .sbar import duty_from_v2, duty_from_v2_clipped, v2_from_duty

__all__ = [
    "LinkParams", "TABLE_I", "EnvelopeLink", "coefficients", "g22", "simulate", "state_matrices",
    "steady_state", "zoh_discretise", "InverseModelController", "LowPassFilter", "TransitionMetrics",
    "transition_metrics", "duty_from_v2", "duty_from_v2_clipped", "v2_from_duty",
]
