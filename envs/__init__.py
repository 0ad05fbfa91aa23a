"""Gymnasium environments of a drone's SBAR receiver during a charging window.

``import envs`` registers

* ``dronewpt/SbarCharging-v0`` - continuous action in [-1, 1] -> d_short in [0, 1]
* ``dronewpt/SbarChargingDiscrete-v0`` - {0: RM, 1: SM} every control period (ON-OFF)

both with a batched ``vector_entry_point``::

    env = gymnasium.make("dronewpt/SbarCharging-v0", scenario="nominal")
    venv = gymnasium.make_vec("dronewpt/SbarCharging-v0", num_envs=1024, vectorization_mode="vector_entry_point")

An env is four parts (gym-electric-motor style), each called once per ``reset`` and once per ``step``:
the scenario part (draws and the reference, :class:`envs.scenario.ScenarioPart`), the plant, the
objective and the observation (:mod:`envs.parts`); a new scenario is one new
:class:`envs.scenario.Draw` (docs/envs.md).

Modules, in the order data flows:

=================  ==========================================================================
``scenario``       scenarios, their draws (``Draw`` parts) and the seeded charge-command
                   generator (the reference): the scenario part
``draw_kernel``    the autoreset's per-window draws, compiled and parallel over windows: each window's own
                   numpy generator driven in place (numpy's C bit generator, numba's port of its ziggurat)
``command_kernel`` the charge command of every step of a batch of windows, compiled (the one source of
                   ``scenario.command_profile``), parallel over the steps on the autoreset's threads
``chunked``        the rule of both: one chunk calls the serial loop (no thread pool started), more the
                   parallel function
``plant``          the world as the env needs it: hover pose error -> true Lm, battery, power
``layout``         the named slots of the state, battery, coefficient, info and constant arrays
``core``           the env's settings and the plant's per-episode plans (ZOH coefficients, initial state)
``parts``          the plant, objective and observation parts of the single and the vector env
``objective``      the domain's objective: overshoot at the stop, short-mode flag, episode cost
``peaks``          the instantaneous peak: envelope peak + the SBAR's harmonic excess (table)
``vector_kernel``  THE env step, once, compiled (numba): link, sub-steps, detuned tank, peak,
                   battery, reward, objective, observation, info; parallel over sub-envs
``duty_sine``      sin(pi d/2) and cos(pi d/2) of the duty by two polynomials (no libm call; numba-free): the
                   SBAR's duty terms of ``vector_kernel``'s step
``modal_plant``    the plant's link model chosen per env (``EnvConfig.link_model``): the
                   mission's exact-mode link (default) or eq. 4's envelope (plans, plant parts)
``modal_step``     the env step on the exact-mode link, compiled (numba): the link's modes,
                   sub-steps with the closed-form commutation, phase-aware peak; the rest of
                   the step is ``vector_kernel``'s helpers
``charging``       the single envs (:class:`SbarChargingEnv`, discrete ON-OFF variant)
``vector``         the batched vector envs (autoreset ``NEXT_STEP``, ``num_threads``)
``sb3_vec``        a stable-baselines3 ``VecEnv`` over the batched env (``rl`` extra)
``history``        a short history of observations (frame stack) for learned policies, SB3 wrapper
``sensing``        the sensing delay of the observation's current fields (scenario sense_delay)
``detuned``        detuned tanks (scenario detuned): complex-envelope plans and steady state
``rollout``        fixed duty sequences replayed on one seeded window, many at once (the oracle's)
``render``         the picture: the episode's current envelope as an RGB array
=================  ==========================================================================

The step is :mod:`envs.modal_step` for both envs (the default ``EnvConfig(link_model="modal")``;
:mod:`envs.vector_kernel` with ``EnvConfig(link_model="envelope")``) (the single env through a per-env entry,
``single_step``; the vector env through ``env_step``); the other modules make plans and keep the
orchestration (reset, seeding, autoreset, info dicts, rendering).
"""

import gymnasium

from .charging import SbarChargingDiscreteEnv, SbarChargingEnv
from .core import EnvConfig, RewardWeights
from .scenario import SCENARIOS, Scenario, get_scenario
from .vector import SbarChargingDiscreteVectorEnv, SbarChargingVectorEnv

__all__ = ["SbarChargingEnv", "SbarChargingDiscreteEnv", "SbarChargingVectorEnv", "SbarChargingDiscreteVectorEnv",
           "EnvConfig", "RewardWeights", "Scenario", "SCENARIOS", "get_scenario", "ENV_ID", "DISCRETE_ENV_ID"]

ENV_ID = "dronewpt/SbarCharging-v0"
DISCRETE_ENV_ID = "dronewpt/SbarChargingDiscrete-v0"

for _id, _ep, _vep in ((ENV_ID, "envs.charging:SbarChargingEnv", "envs.vector:SbarChargingVectorEnv"),
                       (DISCRETE_ENV_ID, "envs.charging:SbarChargingDiscreteEnv",
                        "envs.vector:SbarChargingDiscreteVectorEnv")):
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point=_ep, vector_entry_point=_vep, disable_env_checker=False)
