"""Switching-level (instantaneous) model of the link and the SBAR, event-exact.

Modules, in the order data flows:

==============  ===========================================================================
``circuit``     eq. 1 as per-topology state matrices (inverter legs x SBAR state), devices
``schedule``    the drive: inverter commutations, dead time, SBAR gate windows from d_short
``link``        :class:`SwitchingLink`: exact modal stepping between events, root refinement
``compiled``    the same event loop compiled with numba (the default; ``link`` is the reference)
``mode_rules``  its diode / freewheel rules, numba-free (compiled into it; ``ivp`` calls them as Python)
``result``      :class:`SwitchingResult`: dense samples, per-half-cycle envelope, energies
``ivp``         :func:`simulate_ivp`: the same circuit through ``solve_ivp`` (slow reference)
``plant``       :func:`switching_plant` for :func:`wpt_receiver.paper.run_paper`; eq. 9 check
``stress``      voltage stress: open-load (BMS disconnect) fault, ringing of an edge (stray L, Coss)
``netlist``     the same circuit and devices as a SPICE netlist (ngspice / LTspice; ``dronewpt netlist``)
==============  ===========================================================================

Figures of the waveforms live outside the physics, in :mod:`mission_sim.figures.switching`.
"""

from .circuit import Circuit, SwitchingConfig
from .ivp import simulate_ivp
from .link import SwitchingLink
from .plant import sbar_relation, switching_plant
from .result import SwitchingResult, fundamental
from .schedule import Schedule, make_schedule

__all__ = ["SwitchingConfig", "Circuit", "Schedule", "SwitchingResult", "SwitchingLink", "make_schedule",
           "simulate_ivp", "switching_plant", "fundamental", "sbar_relation"]
