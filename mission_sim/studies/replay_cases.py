"""The replay case runner of sweeps: parameter studies over your own flight logs.

A study with a ``[replay]`` section (:mod:`mission_sim.studies.study`) runs every case as
``dronewpt replay LOG [--pad LAT,LON] [--pads FILE] --set KEY=VALUE ...`` would, summary-only (no time series, no
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
on the replay's mission), plus what a replay itself refuses (no pad within reach, a track, or a re-flight with its charging
hovers, too long for ``sim.traj_dt_s``). The logged battery voltage against each case's pack is warned once per study,
counting the cases outside it (:meth:`ReplayCaseRunner.setup_notes`: ``replay``'s line), not per case.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

from ..setup_warnings import REPLAY_ORIGIN
from .mission_cases import _CACHE_MAX, MissionCaseRunner
from .study import DEFAULT_POLICY, POLICY_KEY, Study, canonical_json

__all__ = ["ReplayCaseRunner", "replay_runner", "load_inputs"]

_INPUTS: dict = {}  # (path, sha256) -> parsed log / pads, once per process (driver or worker)
_SHIPPED: dict = {}  # (kind, path, sha256) -> the file's bytes, sent to a worker that may not see the path
#: a log up to this size is sent to every Dask worker with the warm-up (remote workers need not see the driver's path)
SHIP_MAX_BYTES = 64 * 2**20
#: the keys a replay's own refusals depend on: the track and the detours (pad positions, not their hover times; the
#: coil gap, the trajectory step), then the re-flight's size (the hovers and the mission's speeds too)
_REPLAY_INPUTS = ("pads.", "mission.hover_gap_m", "sim.traj_dt_s")
_SIZE_INPUTS = ("pads.", "mission.", "sim.traj_dt_s")
_PLANS_MAX = 64   # re-flight plans (track, detours) kept by the driver's check: a few MB at most


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def load_inputs(kind: str, path: Path, sha: str | None = None):
    """The parsed log (``kind`` "log": :func:`~mission_sim.mavlink.logs.read_log`) or pads file ("pads":
    :func:`~mission_sim.plans.pads.read_pads`) at ``path``, parsed once per process. ``sha``: the file's
    sha256 when the sweep started; a file changed since is a ``ValueError`` (its rows would mix)."""
    key = (kind, str(path), sha)
    obj = _INPUTS.get(key)
    if obj is None:
        if not Path(path).exists():
            obj = _parse_shipped(kind, Path(path), sha)   # a remote worker: the bytes the driver sent
        else:
            if sha is not None and _sha256(Path(path)) != sha:
                raise ValueError(f"[replay] {kind} {str(path)!r} changed since the sweep started; valid: the file "
                                 "the sweep was prepared with (run the sweep again with a new --out)")
            obj = _parse(kind, Path(path))
        _INPUTS[key] = obj
    return obj


def _parse(kind: str, path: Path):
    if kind == "log":
        from ..mavlink.logs import read_log
        return read_log(path)
    from ..plans.pads import read_pads
    return read_pads(path)


def _parse_shipped(kind: str, path: Path, sha: str | None):
    """The file the driver sent with the warm-up (its sha256 checked), parsed from a temporary copy of the same
    name (the log's name is in its warnings); a one-line ``ValueError`` when it was not sent (too large)."""
    import socket
    import tempfile
    from dataclasses import replace
    data = _SHIPPED.get((kind, str(path), sha))
    if data is None:
        raise ValueError(f"[replay] {kind} {str(path)!r} does not exist on worker {socket.gethostname()!r} and was "
                         f"not sent to it (files up to {SHIP_MAX_BYTES // 2**20} MB are); valid: a {kind} the workers "
                         "see at the same absolute path (a shared folder)")
    if sha is not None and hashlib.sha256(data).hexdigest() != sha:
        raise ValueError(f"[replay] {kind} {str(path)!r}: the bytes received differ from the file's sha256 {sha[:12]}...")
    with tempfile.TemporaryDirectory(prefix="dronewpt-replay-") as tmp:
        copy = Path(tmp) / path.name
        copy.write_bytes(data)
        obj = _parse(kind, copy)
    return replace(obj, path=path) if kind == "log" else obj


class _WarmWithLog:
    """``runner.warm`` as sent to every Dask worker: the log's bytes go with it (once per worker, not with every
    chunk of cases) when it is at most :data:`SHIP_MAX_BYTES`, so workers that do not see the driver's path (other
    machines, ``dronewpt sweep --scheduler``) parse the same file; workers that see it read their own copy."""

    def __init__(self, runner, data: bytes | None):
        self.runner, self.data = runner, data

    def __call__(self):
        if self.data is not None:
            _SHIPPED[("log", str(self.runner.options["log"]), self.runner.log_sha)] = self.data
        self.runner._warm()


def _study_words(msg: str) -> str:
    """A replay's error or warning in the study file's words (its options are ``[replay]`` keys, not command-line
    flags: ``--pad`` is ``[replay] pad``, the pads' frame origin with ``pads``; ``--window T0,T1`` is ``[replay] window
    = [T0, T1]``)."""
    msg = re.sub(r"--window ([\w.+-]+),([\w.+-]+)", r"[replay] window = [\1, \2]", msg)   # (numbers, T0, T1)
    for flag, key in (("--reach", "[replay] reach_m ="), ("--segment", "[replay] segment ="),
                      ("--window", "[replay] window =")):
        msg = msg.replace(flag, key)
    return re.sub(r"--pad\b", "[replay] pad", msg)


def _flat(summary: dict, prefix: str = "") -> dict:
    """The summary's numbers, flags and texts as flat columns (nested tables as ``outer.inner``; lists are
    left out but counted: ``n_detours``, ``n_warnings``, ...). A list key whose value may be null (``*_periods_s``:
    ``armed_periods_s`` of a log whose armed state is unknown) keeps its counted column, ``n_<key>``, null then, so a
    sweep's column does not depend on the log."""
    out = {}
    for k, v in summary.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        elif isinstance(v, (list, tuple)):
            out[f"{prefix}n_{k}"] = len(v)
        elif v is None and k.endswith("_periods_s"):
            out[f"{prefix}n_{k}"] = None
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
    origin : the replay's pad frame origin as the command resolves it (``[replay] pad``, an altitude-less one at the
        take-off spot's altitude; else the take-off spot: :func:`~mission_sim.mavlink.replay.track_from_log`'s
        ``track.pad``), given to every replay and re-flight as the command gives it

    ``input_files`` (set by :func:`replay_runner`): the log's and the pads file's path and sha256, recorded in
    the sweep's ``sweep.json`` so a resume over a changed file names it.
    """

    _check_run_size = False   # the route is the log: the planner's size estimate does not apply; the replay's own
    #                           limit (MAX_REPLAY_SAMPLES, the re-flight's detours included) is checked in check_params
    _pad_origin = REPLAY_ORIGIN   # (run_mission's words for a replayed trajectory's pads)

    def validate_keys(self, keys, example: dict) -> None:
        """The mission studies' refusals, and the keys a replay never reads (``config.check_replay_keys``, as
        ``replay --set``: a grid over ``mission.cruise_altitude_m`` ran identical cases)."""
        from ..config import check_replay_keys
        check_replay_keys(list(keys), "pads" in self.options, "study key")
        super().validate_keys(keys, example)

    def __init__(self, base: dict, make_policy, policy_names, options: dict, log_sha: str, origin=None):
        super().__init__(base, make_policy, policy_names)
        self.options = dict(options)
        self.log_sha = log_sha
        self.origin = origin
        self._checked: dict = {}   # the replay checks' (error, notes) per value set of the keys they read
        self._log_notes: dict[str, int] = {}   # the log's warnings (replay_warnings) -> cases checked with it
        self._plans: dict = {}
        self.input_files: dict = {}

    def __getstate__(self):
        return {**super().__getstate__(), "_checked": {}, "_plans": {}, "_log_notes": {}}

    def log(self):
        return load_inputs("log", self.options["log"], self.log_sha)

    def setup_notes(self) -> tuple:
        """The logged battery voltage against each case's pack, counted once per study with the mission's setup
        warnings (the cases run with ``warn=False``): the line ``dronewpt replay`` gives
        (:func:`~mission_sim.mavlink.replay.battery_voltage_warning`, "the re-flight" with pads), computed once per
        cell count (the pack's range is ``battery.n_series`` x the cell's: the line reads nothing else of the case;
        once per ``battery`` section took the log's median again for every Monte Carlo draw of a capacity)."""
        from ..mavlink.replay import battery_voltage_warning
        log, run = self.log(), "re-flight" if "pads" in self.options else "replay"
        return (("voltage", "a logged battery voltage outside their model pack's open-circuit range",
                 lambda cfg: (cfg.battery.n_series,), lambda cfg: battery_voltage_warning(log, cfg.battery, run)),)

    def check_params(self, params: dict) -> str | None:
        """None if the case would replay, else the error (the mission's own checks first, then the replay's:
        no pad within ``reach_m`` of the track, a track longer than fits at the case's ``sim.traj_dt_s``)."""
        msg = super().check_params(params)
        if msg is not None:
            return msg
        key = tuple(sorted((k, repr(v)) for k, v in params.items() if k.startswith(_SIZE_INPUTS)))
        if key not in self._checked:   # the replay's own checks depend on these keys only: once per value set
            if len(self._checked) > _CACHE_MAX:
                self._checked.clear()
            self._checked[key] = self._replay_error(self.config(params), params)
        error, notes = self._checked[key]
        for text in notes:
            self._log_notes[text] = self._log_notes.get(text, 0) + 1
        return error

    def study_warnings(self, name: str) -> list[str]:
        """The mission's and the logged voltage's lines (:meth:`MissionCaseRunner.study_warnings`), then the log's
        (:func:`~mission_sim.mavlink.replay.replay_warnings`: a log ending armed, reading stopped early, never armed,
        a position gap, a pad far from the track) in the study's words, once each: alone when every checked case
        has it (they depend on the log, the origin and the window: the same in every case), else with the count."""
        checked = 0 if self._checker is None else self._checker.checked
        return super().study_warnings(name) + [
            _study_words(text) if count == checked else
            f"{count:,} of {checked:,} cases of study {name!r} have: {_study_words(text)}"
            for text, count in self._log_notes.items()]

    def _replay_error(self, cfg, params: dict) -> tuple[str | None, tuple]:
        """(None if the case would replay, else its error; the log's warnings for the case's track:
        :func:`~mission_sim.mavlink.replay.replay_warnings`, as its replay's summary has them)."""
        from ..mavlink.replay import replay_span, replay_warnings, resample_track, track_from_log
        from ..plans.refly import check_refly_size, plan_refly
        o, log = self.options, self.log()
        try:
            if "pads" in o:   # the plan (track, detours) once per track-and-pads value set, the size per case
                key = tuple(sorted((k, repr(v)) for k, v in params.items()
                                   if k.startswith(_REPLAY_INPUTS) and not k.endswith(".hover_time_s")))
                plan = self._plans.get(key)
                if plan is None:
                    if len(self._plans) >= _PLANS_MAX:
                        self._plans.clear()
                    try:
                        plan = plan_refly(log, cfg, pad=self.origin, ground_gap_m=o.get("ground_gap_m"),
                                          window=o.get("window"), reach_m=o["reach_m"], segment=o.get("segment"))[:3]
                        plan = (plan, tuple(replay_warnings(log, plan[0])))   # refly_log's: its resampled track
                    except ValueError as exc:
                        plan = exc
                    self._plans[key] = plan
                if isinstance(plan, ValueError):
                    raise plan
                check_refly_size(*plan[0], cfg)
                return None, plan[1]
            gap = cfg.mission.hover_gap_m if o.get("ground_gap_m") is None else o["ground_gap_m"]
            span, _ = replay_span(log, o.get("window"), o.get("segment"))
            track = track_from_log(log, pad=self.origin, ground_gap_m=gap, window=span)
            resample_track(track, cfg.sim.traj_dt_s)
        except ValueError as exc:
            return _study_words(str(exc)), ()
        return None, tuple(replay_warnings(log, track))

    def __call__(self, params: dict) -> dict:
        """The case's replay summary (flat columns), summary-only."""
        from ..config import policy_context
        o = self.options
        cfg = self.config(params)
        policy = self.make_policy(params.get(POLICY_KEY, DEFAULT_POLICY), policy_context(cfg))
        if "pads" in o:
            from ..plans.refly import refly_log
            res = refly_log(self.log(), cfg, policy, pad=self.origin, ground_gap_m=o.get("ground_gap_m"),
                            window=o.get("window"), reach_m=o["reach_m"], segment=o.get("segment"), frame=False,
                            warn=False)
        else:
            from ..mavlink.replay import replay_log
            res = replay_log(self.log(), cfg, policy, pad=self.origin, ground_gap_m=o.get("ground_gap_m"),
                             window=o.get("window"), segment=o.get("segment"), frame=False, warn=False)
        out = _flat(res.summary)
        out.pop("log", None)   # the study's, the same in every row
        out["drone_mass_kg"] = float(cfg.drone.mass_kg)
        return out

    @property
    def warm(self):
        """The warm-up the sweep engine runs once on every worker (:meth:`_warm`), with the log's bytes when it is
        small enough to send (:class:`_WarmWithLog`)."""
        path = Path(self.options["log"])
        small = path.is_file() and path.stat().st_size <= SHIP_MAX_BYTES
        return _WarmWithLog(self, path.read_bytes() if small else None)

    def _warm(self) -> None:
        """Read and parse the log (and the pads) on this worker, then replay the base case once (summary
        only): numba's cache and the coupling table are loaded before the first case."""
        from wpt_receiver.numba_start import cache_loads_without_registries
        cache_loads_without_registries()
        self.log()
        self({})


def _base(study: Study, options: dict, origin, pads) -> dict:
    """The replay's mission dict as ``dronewpt replay`` builds it (``--config`` = ``[study] base``; the pads about
    the frame origin ``origin``)."""
    from ..config import apply_overrides, config_to_dict, load_config, load_config_dict
    if pads is not None:
        from ..plans.refly import refly_base
        d = refly_base(config_to_dict(load_config(study.base_path)), pads, origin, Path(options["pads"]).name)
    else:
        d = load_config_dict(study.base_path)
        d["pads"] = [{"x_m": 0.0, "y_m": 0.0, "z_m": 0.0}]
    if "drone" in options:
        from ..mavlink.calibrate import read_drone_toml
        d = apply_overrides(d, read_drone_toml(options["drone"]))
    return d


def _relative_note(study: Study, key: str) -> str:
    """For a missing file given by a relative path: where it was looked for (the study file's folder, not the
    folder the sweep was started in)."""
    raw = str((study.source.get("replay") or {}).get(key, ""))
    rel = Path(raw).expanduser()
    if not raw or rel.is_absolute():
        return ""
    folder = Path(study.replay[key]).parents[len(rel.parts) - 1]
    return (f" (a relative [replay] {key} = {raw!r} is relative to the study file's folder {str(folder)!r}, not to "
            "the current folder; valid: a path from there, or an absolute one)")


def replay_runner(study: Study, make_policy, policy_names) -> tuple[ReplayCaseRunner, str]:
    """(runner, fingerprint) of a ``[replay]`` study: the files checked and read here, on the driver (a
    missing file, a folder, a file that is not a flight log: one-line ``ValueError`` / ``FileNotFoundError``
    naming it). The fingerprint covers the files' contents, the options and the mission, so a changed log
    makes new case ids."""
    from ..mavlink.replay import replay_span, track_from_log
    from ..validation import check_regular_file
    o = dict(study.replay)
    for key, valid in (("log", "a .tlog, .bin or .ulg flight log"), ("pads", "a CSV or GeoJSON pads file"),
                       ("drone", "a TOML file with a [drone] table")):
        if key in o:
            try:
                check_regular_file(o[key], f"[replay] {key}", valid)
            except FileNotFoundError as exc:
                raise FileNotFoundError(f"{exc}{_relative_note(study, key)}") from None
    log_sha = _sha256(o["log"])
    try:
        log = load_inputs("log", o["log"], log_sha)
        span, _ = replay_span(log, o.get("window"), o.get("segment"))
        # no usable position (not a flight log): one line naming the file; the frame origin as the command's
        origin = track_from_log(log, pad=o.get("pad"), window=span).pad
    except ValueError as exc:
        msg, name = _study_words(str(exc)), f"{Path(o['log']).name}: "
        raise ValueError(f"[replay] log {str(o['log'])!r}: {msg[len(name):]}" if msg.startswith(name) else msg) from None
    pads_sha = _sha256(o["pads"]) if "pads" in o else None
    pads = load_inputs("pads", o["pads"], pads_sha) if "pads" in o else None
    try:
        base = _base(study, o, origin, pads)
    except ValueError as exc:   # e.g. a pad of the pads file far from the frame origin ([replay] pad)
        raise ValueError(_study_words(str(exc))) from None
    runner = ReplayCaseRunner(base, make_policy, policy_names, o, log_sha, origin)
    runner.input_files = {f"[replay] {k}": {"path": str(o[k]), "sha256": sha}
                          for k, sha in (("log", log_sha), ("pads", pads_sha)) if sha is not None}
    ident = {"runner": "replay v1", "base": base, "log": log_sha, "pads": pads_sha,
             "options": {k: [v.lat_deg, v.lon_deg, v.alt_m] if k == "pad" else v for k, v in o.items()
                         if k not in ("log", "pads", "drone")}}
    return runner, hashlib.sha256(canonical_json(ident).encode()).hexdigest()[:16]
