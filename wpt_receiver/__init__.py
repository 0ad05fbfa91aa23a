"""wpt_receiver: the WPT link with an SBAR receiver, as modelled in the paper.

Depends on nothing else of dronewpt. Modules, in the order data flows:

======================  =====================================================================
``params``              :class:`LinkParams`, :data:`TABLE_I` (Table I)
``coupling``            Lm(pose) of two circular coils (Maxwell / Neumann), lookup tables
``diskcache``           on-disk cache of arrays by content hash (coupling table, ZOH results)
``lti``                 SISO transfer functions and their ZOH without importing scipy.signal
``coupling_kernel``     the coupling table's lookup (B-spline, loop integral), numba: the one copy
``envelope``            envelope model (eq. 3-8): exact ZOH stepping, steady states, G22
``sbar``                SBAR duty mapping f(d_short) (eq. 9), its inverse, the rectifier rule
``inverse_controller``  the proposed controller (Fig. 5): low-pass, G22^-1, f^-1
``references``          step, ramp and proposed V2* trajectories
``metrics``             peak, final value and overshoot of a transition (Table II)
``paper``               Table II / Fig. 6 as a reusable scenario on either plant model
``switching/``          switching-level (instantaneous, event-exact) model of eq. 1 and the SBAR
``devices``             diodes / switches (piecewise linear), the shipped parts table, presets
``edge_losses``         energy per switching edge (Coss, Cj, overlap, recovery) from datasheet data
``thermal``             junction-temperature fixed point (Rth jc / cs / sink), thermal runaway
``peak``                SBAR harmonic balance: v2 with its quadrature, instantaneous peak of i2
``modal``               envelope on the exact coupled modes w/sqrt(1 -+ k), SBAR v2 balanced
``modal_kernel``        the exact-mode link step compiled (numba, imported on demand): modes per Lm,
                        ZOH per dt, energies, v2 with quadrature and peak from a table
``modal_link``          the exact-mode link's layout, constants and cached table without numba (for
                        ``modal_kernel`` and a mission run by the ahead-of-time build)
``kernel_cache``        numba's cache of a kernel dropped when a module it compiles in changes; an
                        installed copy's numba cache kept out of site-packages
``notices``             :class:`DronewptWarning`; the one notice when numba compiles our kernels (logged)
``numba_start``         numba's start-up without the scipy.linalg package (its BLAS probe's module alone),
                        cache loads without numba's registries
``sizing``              rectifier rating, parts and mass per policy (switching or envelope runs)
``detuning``            C1 / C2 off resonance: overshoot table of the controllers
``c_export``            the controller (Fig. 5) as generated C99 for a DSP, test vectors, op count
``tolerance``           component-tolerance draws: RM steady state and transient peaks (complex envelope)
``rm_state``            the complex envelope's RM steady state in closed form (``tolerance``'s, re-exported there)
``tolerance_kernel``    the tolerance transient compiled with numba (imported on demand)
======================  =====================================================================
"""

from .kernel_cache import place_numba_cache

place_numba_cache(__path__[0])      # an installed copy: numba's cache in dronewpt's disk cache, not site-packages

import os as _os

if _os.environ.get("DRONEWPT_CACHE_DIR"):   # a file or a folder that cannot be written: said once, not ignored silently
    from .diskcache import warn_unusable
    from .kernel_cache import numba_fallback
    warn_unusable(numba_fallback())
del _os

from .notices import listen_for_compilation

listen_for_compilation()            # one notice when numba first compiles one of our kernels (a silent ~40 s)

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
