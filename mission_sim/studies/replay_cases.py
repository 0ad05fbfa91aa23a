"""The replay case runner of sweeps: parameter studies over your own flight logs.

A study with a ``[replay]`` section (:mod:`mission_sim.studies.study`) runs every case as
``dronewpt replay LOG [--pads FILE] --set KEY=VALUE ...`` would, summary-only (no time series, no
figure), with the case's values as the ``--set`` keys (``drone.mass_kg``, ``battery.capacity_ah``,
``mission.hover_time_s``, ``pads.0.hover_time_s``, ``link.*``, ``charger.*``, ... and ``policy``):

* with ``pads``: the what-if re-flight (:func:`mission_sim.plans.refly.refly_log`): the flight time
  the pads buy against the logged flight and against the same detours flown unpowered, energies,
  SoC (final, minimum), peak I2;
* without: the replay (:func:`mission_sim.mavlink.replay.replay_log`): energies, final / minimum
  SoC, peak I2 and the comparison with the logged power (energy error, equivalent mass).

The log (and the pads file) is read and parsed once per process: on the driver when the study is
prepared (a missing file, or one that is not a flight log, is refused there with one line), and on
every Dask worker in :meth:`ReplayCaseRunner.warm`, never per case. Keys and values are checked
before anything runs exactly as the mission runner checks them (:class:`.mission_cases.MissionParamChecker`,
on the replay's mission), plus what a replay itself refuses (no pad within reach, a track too long
for ``sim.traj_dt_s``).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from .mission_cases import MissionCaseRunner
from .study import DEFAULT_POLICY, POLICY_KEY, Study, canonical_json

__all__ = ["ReplayCaseRunner", "replay_runner", "load_inputs"]

_INPUTS: dict = {}  # (path, sha256) -> parsed log / pads, once per process (driver or worker)
#: the keys a replay's own refusals depend on (pad positions, not their hover times; the coil gap, the trajectory step)
_REPLAY_INPUTS = ("pads.", "mission.hover_gap_m", "sim.traj_dt_s")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def load_inputs(kind: str, path: Path, sha: str | None = None):
    """The parsed log (``kind`` "log": :func:`~mission_sim.mavlink.logs.read_log`) or pads file ("pads":
    :func:`~mission_sim.plans.pads.read_pads`) at ``path``, parsed once per process. ``sha``: the file's
    sha256 when the sweep started; a file changed since is a ``ValueError`` (its rows would mix)."""
    key = (kind, str(path), sha)
    obj = _INPUTS.get(key)
    if obj is None:
        if sha is not None and _sha256(Path(path)) != sha:
            raise ValueError(f"[replay] {kind} {str(path)!r} changed since the sweep started; valid: the file the "
                             "sweep was prepared with (run the sweep again with a new --out)")
        if kind == "log":
            from ..mavlink.logs import read_log
            obj = read_log(path)
        else:
            from ..plans.pads import read_pads
            obj = read_pads(path)
        _INPUTS[key] = obj
    return obj


def _study_words(msg: str) -> str:
    """A replay's error in the study file's words (its options are ``[replay]`` keys, not command-line flags)."""
    for flag, key in (("--reach", "[replay] reach_m ="), ("--segment", "[replay] segment ="),
                      ("--window", "[replay] window ="), ("check --pad", "check the pads")):
        msg = msg.replace(flag, key)
    return msg


def _flat(summary: dict, prefix: str = "") -> dict:
    """The summary's numbers, flags and texts as flat columns (nested tables as ``outer.inner``; lists are
    left out but counted: ``n_detours``, ``n_warnings``, ...)."""
    out = {}
    for k, v in summary.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        elif isinstance(v, (list, tuple)):
            out[f"{prefix}n_{k}"] = len(v)
        elif v is None or isinstance(v, (bool, int, float, str)):
            out[f"{prefix}{k}"] = v
    return out


class ReplayCaseRunner(MissionCaseRunner):
    """``run_case`` for replays: ``--set`` overrides + ``policy`` -> the replay's (or re-flight's) summary.

    base : the replay's mission dict, ``--drone`` file laid over it: with pads
        :func:`~mission_sim.plans.refly.refly_base` of the ``--config`` mission, without them the
        ``--config`` mission with one pad at the frame origin (as ``dronewpt replay`` builds them)
    options : the ``[replay]`` section (paths resolved)
    log_sha : the log's sha256 (checked where it is read; the pads are in ``base`` already)
    """

    _check_run_size = False   # the route is the log: the planner's size estimate does not apply (see check_params)

    def __init__(self, base: dict, make_policy, policy_names, options: dict, log_sha: str):
        super().__init__(base, make_policy, policy_names)
        self.options = dict(options)
        self.log_sha = log_sha
        self._refused: dict = {}

    def __getstate__(self):
        return {**super().__getstate__(), "_refused": {}}

    def log(self):
        return load_inputs("log", self.options["log"], self.log_sha)

    def check_params(self, params: dict) -> str | None:
        """None if the case would replay, else the error (the mission's own checks first, then the replay's:
        no pad within ``reach_m`` of the track, a track longer than fits at the case's ``sim.traj_dt_s``)."""
        msg = super().check_params(params)
        if msg is not None:
            return msg
        key = tuple(sorted((k, repr(v)) for k, v in params.items()
                           if k.startswith(_REPLAY_INPUTS) and not k.endswith(".hover_time_s")))
        if key not in self._refused:   # the replay's own checks depend on these keys only: once per value set
            self._refused[key] = self._replay_error(self.config(params))
        return self._refused[key]

    def _replay_error(self, cfg) -> str | None:
        from ..mavlink.replay import replay_span, resample_track, track_from_log
        from ..plans.refly import plan_refly
        o, log = self.options, self.log()
        try:
            if "pads" in o:
                plan_refly(log, cfg, ground_gap_m=o.get("ground_gap_m"), window=o.get("window"),
                           reach_m=o["reach_m"], segment=o.get("segment"))
            else:
                gap = cfg.mission.hover_gap_m if o.get("ground_gap_m") is None else o["ground_gap_m"]
                span, _ = replay_span(log, o.get("window"), o.get("segment"))
                resample_track(track_from_log(log, ground_gap_m=gap, window=span), cfg.sim.traj_dt_s)
        except ValueError as exc:
            return _study_words(str(exc))
        return None

    def __call__(self, params: dict) -> dict:
        """The case's replay summary (flat columns), summary-only."""
        from ..config import policy_context
        o = self.options
        cfg = self.config(params)
        policy = self.make_policy(params.get(POLICY_KEY, DEFAULT_POLICY), policy_context(cfg))
        if "pads" in o:
            from ..plans.refly import refly_log
            res = refly_log(self.log(), cfg, policy, ground_gap_m=o.get("ground_gap_m"), window=o.get("window"),
                            reach_m=o["reach_m"], segment=o.get("segment"), frame=False, warn=False)
        else:
            from ..mavlink.replay import replay_log
            res = replay_log(self.log(), cfg, policy, ground_gap_m=o.get("ground_gap_m"), window=o.get("window"),
                             segment=o.get("segment"), frame=False, warn=False)
        out = _flat(res.summary)
        out.pop("log", None)   # the study's, the same in every row
        out["drone_mass_kg"] = float(cfg.drone.mass_kg)
        return out

    def warm(self) -> None:
        """Read and parse the log (and the pads) on this worker, then replay the base case once (summary
        only): numba's cache and the coupling table are loaded before the first case."""
        from wpt_receiver.numba_start import cache_loads_without_registries
        cache_loads_without_registries()
        self.log()
        self({})


def _base(study: Study, options: dict, log, pads) -> dict:
    """The replay's mission dict as ``dronewpt replay`` builds it (``--config`` = ``[study] base``)."""
    from ..config import apply_overrides, config_to_dict, load_config, load_config_dict
    from ..mavlink.replay import default_pad
    if pads is not None:
        from ..plans.refly import refly_base
        d = refly_base(config_to_dict(load_config(study.base_path)), pads, default_pad(log), Path(options["pads"]).name)
    else:
        d = load_config_dict(study.base_path)
        d["pads"] = [{"x_m": 0.0, "y_m": 0.0, "z_m": 0.0}]
    if "drone" in options:
        from ..mavlink.calibrate import read_drone_toml
        d = apply_overrides(d, read_drone_toml(options["drone"]))
    return d


def replay_runner(study: Study, make_policy, policy_names) -> tuple[ReplayCaseRunner, str]:
    """(runner, fingerprint) of a ``[replay]`` study: the files checked and read here, on the driver (a
    missing file, a folder, a file that is not a flight log: one-line ``ValueError`` / ``FileNotFoundError``
    naming it). The fingerprint covers the files' contents, the options and the mission, so a changed log
    makes new case ids."""
    from ..mavlink.replay import replay_span, track_from_log
    from ..validation import check_regular_file
    o = dict(study.replay)
    check_regular_file(o["log"], "[replay] log", "a .tlog, .bin or .ulg flight log")
    for key, valid in (("pads", "a CSV or GeoJSON pads file"), ("drone", "a TOML file with a [drone] table")):
        if key in o:
            check_regular_file(o[key], f"[replay] {key}", valid)
    log_sha = _sha256(o["log"])
    try:
        log = load_inputs("log", o["log"], log_sha)
        span, _ = replay_span(log, o.get("window"), o.get("segment"))
        track_from_log(log, window=span)   # no usable position (not a flight log): one line naming the file
    except ValueError as exc:
        msg, name = _study_words(str(exc)), f"{Path(o['log']).name}: "
        raise ValueError(f"[replay] log {str(o['log'])!r}: {msg[len(name):]}" if msg.startswith(name) else msg) from None
    pads_sha = _sha256(o["pads"]) if "pads" in o else None
    pads = load_inputs("pads", o["pads"], pads_sha) if "pads" in o else None
    base = _base(study, o, log, pads)
    runner = ReplayCaseRunner(base, make_policy, policy_names, o, log_sha)
    ident = {"runner": "replay v1", "base": base, "log": log_sha, "pads": pads_sha,
             "options": {k: v for k, v in o.items() if k not in ("log", "pads", "drone")}}
    return runner, hashlib.sha256(canonical_json(ident).encode()).hexdigest()[:16]
