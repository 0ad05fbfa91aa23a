"""The mission case runner of sweeps and the check of every case's values before a sweep starts.

:class:`MissionCaseRunner` turns a case's parameters (dotted overrides + ``policy``) into a
:class:`~mission_sim.config.MissionConfig`, a policy and ``run_mission(...).summary``.

:class:`MissionParamChecker` validates a case's values exactly as the runner would (the mission
config's own checks: types, ranges, cross-field limits, and the run-size estimate of
:mod:`mission_sim.world.budget`), but fast enough for 10^5-10^6 cases: only the sections a case
changes are rebuilt, each distinct section value set is checked once (cached), and the rest of the
config is the base's. About 5-15 us per case instead of ~200 us for a full rebuild.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable

from wpt_receiver.params import FREQUENCY_TOLERANCE

from ..setup_warnings import HOME_ORIGIN, PAD_HEIGHT_WARN_M
from .study import DEFAULT_POLICY, POLICY_KEY

__all__ = ["MissionCaseRunner", "MissionParamChecker"]

_CACHE_MAX = 200_000  # section value sets remembered (continuous Monte Carlo draws are all distinct)


class MissionParamChecker:
    """``checker(overrides) -> None | error message`` for a base mission dict (``config_to_dict``).
    ``run_size``: also the planned mission's run-size estimate (False for replays: the log is the route).
    ``notes``: more kinds of setup warning to count, ``(kind, description, what, check)`` each (as :data:`KINDS`;
    ``what(cfg)``: a tuple of what the warning reads, the cached section objects or their values (keyed by identity,
    kept with the result: equal sections are one object; ``check`` runs once per distinct tuple), ``check(cfg)``: its
    line or None), e.g. a replay's logged battery voltage, ``what`` = ``(cfg.battery.n_series,)``
    (:meth:`~mission_sim.studies.replay_cases.ReplayCaseRunner.setup_notes`)."""

    def __init__(self, base: dict, run_size: bool = True, notes: tuple = (), pad_origin: str = HOME_ORIGIN):
        from ..config import config_from_dict

        self.base = base
        self.run_size = run_size
        self.pad_origin = pad_origin   # the pads' frame origin, as the far pad's line names it
        self.notes = tuple(notes)
        self.kinds = {**self.KINDS, **{kind: text for kind, text, _, _ in self.notes}}
        self.cfg = config_from_dict(base)
        self._sections: dict[tuple, object] = {}
        self._sizes: dict[tuple, str | None] = {}
        self._notes: dict[tuple, tuple] = {}    # section identities -> (the sections, their setup warnings)
        self.warned: dict[str, list] = {}        # kind of setup warning -> [cases with one, an example message]
        self.checked = 0                         # cases whose values passed

    def _note(self, cfg, policy=None) -> None:
        """Count ``cfg``'s setup warnings (:mod:`mission_sim.setup_warnings`; its cases are made with
        ``policy_context``, so no policy warning; the pad gate's against the case's ``policy``'s declared RM -> SM
        overshoot, as ``dronewpt mission`` checks it: :func:`~mission_sim.setup_warnings.short_mode_rating_warning`),
        each computed once per distinct value of what it reads (the
        cached section objects: keys of identities, ~1 us a case; ~50 us for each new link, e.g. a Monte Carlo
        draw of ``link.vdc_v``). A far pad (:func:`~mission_sim.setup_warnings.far_pad_warnings`) counts whatever
        the route, about :attr:`pad_origin` (``run_mission``'s rule); a payload release with no payload left
        (:func:`~mission_sim.setup_warnings.payload_warnings`) when the cases fly the config's route (``run_size``;
        a replay's route is its log's: none)."""
        from ..setup_warnings import (far_pad_warnings, link_frequency_warning, link_range_warning,
                                      payload_warnings, ring_down_warning, short_mode_rating_warning,
                                      unreached_pad_warnings)

        link = (cfg.link, cfg.coupling, cfg.battery.n_series, cfg.charger.cv_cell_v, cfg.mission.hover_gap_m)
        route = (cfg.waypoints, cfg.mission, *cfg.pads) if cfg.waypoints else ()
        self.checked += 1
        checks = [("link", link, link_range_warning), ("freq", (cfg.link, cfg.coupling), link_frequency_warning),
                  ("rated", (cfg.link, cfg.coupling, policy), lambda c: short_mode_rating_warning(c, policy)),
                  ("ring", (cfg.link, cfg.coupling), ring_down_warning),
                  ("pad", route, unreached_pad_warnings),
                  ("far", tuple(cfg.pads), lambda c: far_pad_warnings(c, self.pad_origin)),
                  ("payload", (cfg.drone, cfg.waypoints) if self.run_size else (), payload_warnings)]
        checks += [(kind, what(cfg), check) for kind, _, what, check in self.notes]
        for kind, what, check in checks:
            if not what:
                continue
            key = (kind, *map(id, what))
            hit = self._notes.get(key)
            if hit is None:
                if len(self._notes) > _CACHE_MAX:
                    self._notes.clear()
                got = check(cfg)
                hit = self._notes[key] = (what, [got] if isinstance(got, str) else list(got or ()))
            if hit[1]:
                seen = self.warned.setdefault(kind, [0, hit[1][0]])
                seen[0] += 1

    #: the kinds of setup warning a study line counts: what the cases have (``notes`` add theirs)
    KINDS = {"link": "a link outside the exact-mode model's checked range",
             "freq": f"a link.f_hz more than a factor {FREQUENCY_TOLERANCE:g} off the coil pair's tanks' resonance",
             "rated": "a coupling.tx_min_k below the coupling where the short-mode I2 reaches link.rated_i2_a",
             "ring": "a pad switch-off ring-down slower than 1 s (tau = 2 L1 / (R1 + 2 Ron))",
             "pad": "a pad their route never energises",
             "far": f"a pad more than {PAD_HEIGHT_WARN_M:g} m above or below its frame's origin",
             "payload": "a payload release with no payload left to drop"}

    def study_warnings(self, name: str) -> list[str]:
        """One line per kind of setup warning (:data:`KINDS`, ``notes``) some of the study's (``name``) checked cases
        have: how many cases have one, and the first such case's message as an example; [] when none has any."""
        return [f"{count:,} of {self.checked:,} cases of study {name!r} have {self.kinds[kind]}, e.g.: {text}"
                for kind, (count, text) in self.warned.items()]

    def _section(self, sec: str, values: dict):
        from ..config import check_seed, section_from_dict

        if sec == "seed":
            return check_seed(values["seed"])
        if sec.startswith("pads."):
            return section_from_dict(sec, {**self.base["pads"][int(sec[5:])], **values})
        return section_from_dict(sec, {**self.base.get(sec, {}), **values})

    def _cached_section(self, sec: str, values: dict):
        key = (sec, tuple((n, type(v).__name__, v) for n, v in values.items()))
        obj = self._sections.get(key)
        if obj is None:
            if len(self._sections) > _CACHE_MAX:
                self._sections.clear()
            try:
                obj = self._section(sec, values)
            except ValueError as exc:
                obj = ValueError(str(exc))
            self._sections[key] = obj
        if isinstance(obj, ValueError):
            raise obj
        return obj

    def _size_error(self, cfg) -> str | None:
        from ..world.budget import check_run_size

        key = (cfg.mission, cfg.pads, cfg.sim)
        if key not in self._sizes:
            if len(self._sizes) > _CACHE_MAX:
                self._sizes.clear()
            try:
                check_run_size(cfg)
                self._sizes[key] = None
            except ValueError as exc:
                self._sizes[key] = str(exc).replace("; use --force to run it anyway", "")
        return self._sizes[key]

    def __call__(self, overrides: dict, policy=None) -> str | None:
        """None if the case's ``overrides`` build its mission (its setup warnings counted, the pad gate's against
        ``policy``, a policy object or None), else the error."""
        groups: dict[str, dict] = {}
        for k, v in overrides.items():
            sec, _, name = str(k).rpartition(".")
            groups.setdefault(sec or "seed", {})[name] = v
        kw, pads = {}, list(self.cfg.pads)
        try:
            for sec, values in groups.items():
                obj = self._cached_section(sec, values)
                if sec.startswith("pads."):
                    pads[int(sec[5:])] = obj
                else:
                    kw[sec] = obj
            cfg = dataclasses.replace(self.cfg, pads=tuple(pads), **kw)  # cross-field checks
        except ValueError as exc:
            return str(exc)
        err = self._size_error(cfg) if self.run_size else None
        if err is None:
            self._note(cfg, policy)
        return err


class MissionCaseRunner:
    """``run_case`` for missions: overrides -> MissionConfig -> policy -> ``run_mission(...).summary``.

    base : the base mission as a plain dict (``config_to_dict``)
    make_policy : ``make_policy(name, PolicyContext) -> Policy`` (the CLI passes ``policies.make``;
        picklable by reference, so workers import ``policies`` themselves)
    policy_names : the valid policy names (checked before a sweep starts), or None
    """

    _check_run_size = True   # the planned mission's run-size estimate is part of a case's check
    _pad_origin = HOME_ORIGIN   # the pads' frame origin, as the far pad's line names it (a replay's: its own)

    def __init__(self, base: dict, make_policy: Callable, policy_names: Iterable[str] | None = None):
        self.base = base
        self.make_policy = make_policy
        self.policy_names = None if policy_names is None else tuple(policy_names)
        self._checker = None
        self._specs: dict[str, str | None] = {}   # a policy spec -> its error (None: valid), made once
        self._made: dict = {}   # a policy spec -> a policy made with the default context (its declared overshoot)

    def __getstate__(self):  # the checker's caches stay on the driver
        return {**self.__dict__, "_checker": None, "_specs": {}, "_made": {}}

    def config(self, params: dict):
        from ..config import apply_overrides, config_from_dict

        overrides = {k: v for k, v in params.items() if k != POLICY_KEY}
        return config_from_dict(apply_overrides(self.base, overrides))

    def validate_keys(self, keys: Iterable[str], example: dict) -> None:
        """Unknown keys raise ``ValueError`` naming the key (apply_overrides' validation), and so do the keys read
        with the base mission's files (:data:`~mission_sim.plans.FILE_READ_KEYS`: a case's value changed nothing)."""
        from ..config import apply_overrides, check_route_keys
        from ..plans import FILE_READ_KEYS

        for k in keys:
            if k in FILE_READ_KEYS:
                raise ValueError(f"study key {k!r} is invalid: it is read with the mission and pads files when the "
                                 "base mission is loaded, so a case's value would change nothing; valid: set it in "
                                 "the [study] base file (one study per value)")
        check_route_keys(self.base, list(keys), "study key")   # (every case the same mission)
        apply_overrides(self.base, {k: example[k] for k in keys if k != POLICY_KEY})

    def check_params(self, params: dict) -> str | None:
        """None if the case would build its mission, else the error (naming the key and value)."""
        policy = params.get(POLICY_KEY, DEFAULT_POLICY)
        if self.policy_names is not None:
            err = self._policy_error(policy)
            if err is not None:
                return err
        if self._checker is None:
            self._checker = MissionParamChecker(self.base, self._check_run_size, self.setup_notes(),
                                                self._pad_origin)
        return self._checker({k: v for k, v in params.items() if k != POLICY_KEY}, self._policy_for_notes(policy))

    def _policy_for_notes(self, spec):
        """The case's policy as the setup warnings read it (its name and declared ``rm_sm_overshoot``), made once per
        spec with the default context; None when it cannot be made (its error is the case's own)."""
        if not isinstance(spec, str):
            return None
        if spec not in self._made:
            try:
                self._made[spec] = self.make_policy(spec, None)
            except Exception:   # noqa: BLE001 (the case reports it when it runs)
                self._made[spec] = None
        return self._made[spec]

    def _policy_error(self, policy) -> str | None:
        """None if ``policy`` is a valid name or spec (``model_based_budget:0.02``, ``rl:PATH``, as ``--policy``
        takes them: the spec is made once, with the default context, to check its parameter), else the error."""
        if not isinstance(policy, str) or policy.partition(":")[0] not in self.policy_names:
            return f"policy={policy!r} is invalid; valid values: {', '.join(sorted(self.policy_names))} (or NAME:PARAMETER)"
        if ":" not in policy:
            return None
        made = self._specs
        if policy not in made:
            try:
                self.make_policy(policy, None)
                made[policy] = None
            except (ValueError, FileNotFoundError) as exc:
                made[policy] = str(exc)
        return made[policy]

    def setup_notes(self) -> tuple:
        """The runner's own kinds of setup warning, counted per study with the mission's (``MissionParamChecker``'s
        ``notes``): none for missions."""
        return ()

    def study_warnings(self, name: str) -> list[str]:
        """The setup warnings of the cases checked so far, once for the study
        (:meth:`MissionParamChecker.study_warnings`)."""
        return [] if self._checker is None else self._checker.study_warnings(name)

    def __call__(self, params: dict) -> dict:
        """The case's summary; summary-only (``run_mission(frame=False)``: no DataFrame, no figure)."""
        from ..config import policy_context
        from ..world.runner import run_mission

        cfg = self.config(params)
        policy = self.make_policy(params.get(POLICY_KEY, DEFAULT_POLICY), policy_context(cfg))
        return dict(run_mission(cfg, policy, frame=False, warn=False).summary)   # warned once per study

    def warm(self) -> None:
        """Run the base mission once (summary only): imports, the numba cache and the coupling table are
        loaded before the first case (the sweep engine calls this once on every worker). The worker's cached
        kernels load without numba's typing/lowering registries (~0.3 s of CPU per worker; a case that compiles
        still loads them: :func:`wpt_receiver.numba_start.cache_loads_without_registries`)."""
        from wpt_receiver.numba_start import cache_loads_without_registries
        cache_loads_without_registries()
        self({})
