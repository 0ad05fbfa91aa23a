"""Hyperparameters from a file in rl-baselines3-zoo style (YAML or JSON).

Accepted shapes: the algorithm's keyword arguments at top level, or nested under one key (the
env id, e.g. ``dronewpt/SbarCharging-v0:``, as in the zoo's ``hyperparams/ppo.yml``). Zoo keys
that are not model arguments are taken out: ``n_timesteps`` and ``n_envs`` (returned apart, the
caller's explicit values win), ``policy`` (must be ``MlpPolicy``), ``normalize`` (``train`` always
normalises observations). ``policy_kwargs`` may be a mapping or the zoo's string
``"dict(net_arch=[64, 64], log_std_init=-1.5)"`` (keyword literals only; parsed with ``ast``,
never evaluated). Schedules such as ``lin_3e-4`` are not supported (an error names the value).
:func:`check_hyperparams` checks every key against the algorithm's keyword arguments (name, type from
its default, a plausible range for the common ones) so a bad file fails before anything is created.
"""

from __future__ import annotations

import ast
import inspect
import json
from pathlib import Path

from mission_sim.validation import YAML_NUMBER_NOTE, Range, check_range, check_regular_file

__all__ = ["load_hyperparams", "parse_policy_kwargs", "check_hyperparams", "HP_RANGES"]

_ZOO_ONLY = ("n_timesteps", "n_envs", "policy", "normalize")
#: keyword arguments ``train`` sets itself (or that a file cannot give: classes, callables)
_SET_BY_TRAIN = ("self", "policy", "env", "seed", "verbose", "device", "tensorboard_log", "_init_setup_model",
                 "action_noise", "replay_buffer_class", "rollout_buffer_class")
_UNIT, _BIG = Range(0.0, 1.0), 10**9
#: plausible ranges of the common SB3 arguments (the others: type only)
HP_RANGES = {
    "learning_rate": Range(0.0, 1.0, lo_open=True), "gamma": Range(0.0, 1.0, lo_open=True),
    "gae_lambda": _UNIT, "clip_range": Range(0.0, 10.0, lo_open=True), "clip_range_vf": Range(0.0, 10.0, lo_open=True),
    "ent_coef": Range(0.0, 10.0), "vf_coef": Range(0.0, 10.0), "max_grad_norm": Range(0.0, 1e6, lo_open=True),
    "target_kl": Range(0.0, 10.0, lo_open=True), "tau": Range(0.0, 1.0, lo_open=True),
    "exploration_fraction": _UNIT, "exploration_initial_eps": _UNIT, "exploration_final_eps": _UNIT,
    "n_steps": Range(1, _BIG, integer=True), "batch_size": Range(1, _BIG, integer=True),
    "n_epochs": Range(1, 10_000, integer=True), "buffer_size": Range(1, _BIG, integer=True),
    "learning_starts": Range(0, _BIG, integer=True), "train_freq": Range(1, _BIG, integer=True),
    "gradient_steps": Range(-1, 10_000, integer=True), "target_update_interval": Range(1, _BIG, integer=True),
    "sde_sample_freq": Range(-1, _BIG, integer=True), "stats_window_size": Range(1, _BIG, integer=True),
}


def parse_policy_kwargs(value) -> dict:
    """``policy_kwargs`` as a dict: a mapping, or the zoo's ``"dict(k=literal, ...)"`` string."""
    if isinstance(value, dict):
        return dict(value)
    if not isinstance(value, str):
        raise ValueError(f"policy_kwargs={value!r} is invalid; valid: a mapping or a 'dict(key=literal, ...)' string")
    try:
        node = ast.parse(value.strip(), mode="eval").body
        if isinstance(node, ast.Dict):
            return ast.literal_eval(node)
        if not (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "dict" and not node.args):
            raise ValueError
        return {kw.arg: ast.literal_eval(kw.value) for kw in node.keywords}
    except (SyntaxError, ValueError) as exc:
        raise ValueError(f"policy_kwargs={value!r} is invalid; valid: 'dict(key=literal, ...)' with literal "
                         "values only (no activation_fn=nn.ReLU etc.)") from exc


def _read(path: Path) -> dict:
    suffix = path.suffix.lower()
    if suffix not in (".json", ".yml", ".yaml"):
        raise ValueError(f"hyperparams file {str(path)!r} is invalid; valid suffixes: .yml, .yaml, .json")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"hyperparams file {str(path)!r} is not a UTF-8 text file (byte {exc.start})") from None
    if suffix == ".json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"hyperparams file {str(path)!r} is not valid JSON: {exc}") from None
    import yaml
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        raise ValueError(f"hyperparams file {str(path)!r} is not valid YAML: "
                         f"{getattr(exc, 'problem', None) or exc}{where}") from None


def load_hyperparams(path, algo_cls=None) -> tuple[dict, dict]:
    """``(model kwargs, zoo extras)`` from a YAML / JSON file; extras holds ``n_timesteps`` / ``n_envs``.
    With ``algo_cls`` (``stable_baselines3.PPO`` ...) the kwargs are checked by :func:`check_hyperparams`."""
    path = check_regular_file(path, "hyperparams file")
    data = _read(path)
    if not isinstance(data, dict):
        raise ValueError(f"hyperparams file {str(path)!r} is invalid; valid: a mapping of keyword arguments")
    if len(data) == 1 and isinstance(next(iter(data.values())), dict) and next(iter(data)) != "policy_kwargs":
        data = next(iter(data.values()))   # zoo style: nested under the env id
    hp = {k: v for k, v in data.items() if k not in _ZOO_ONLY}
    extras = {k: data[k] for k in ("n_timesteps", "n_envs") if k in data}
    if data.get("policy", "MlpPolicy") != "MlpPolicy":
        raise ValueError(f"policy={data['policy']!r} in {path} is invalid; valid value: MlpPolicy")
    for k, v in hp.items():
        if isinstance(v, str) and k != "policy_kwargs" and v.startswith(("lin_", "linear_")):
            raise ValueError(f"{k}={v!r} in {path} is invalid; schedules are not supported, give a number")
    if "policy_kwargs" in hp:
        hp["policy_kwargs"] = parse_policy_kwargs(hp["policy_kwargs"])
    for k in ("n_timesteps", "n_envs"):
        if k in extras:
            check_range(f"hyperparams file {str(path)!r}: {k}", extras[k], Range(1, _BIG, integer=True))
            extras[k] = int(float(extras[k]))
    if algo_cls is not None:
        try:
            check_hyperparams(hp, algo_cls)
        except ValueError as exc:
            raise ValueError(f"hyperparams file {str(path)!r}: {exc}") from None
    return hp, extras


def check_hyperparams(hp: dict, algo_cls) -> None:
    """``ValueError`` naming the first key of ``hp`` that ``algo_cls`` (an SB3 algorithm class) does not take,
    whose value has the wrong type for the argument's default (number, integer, true/false) or lies outside
    :data:`HP_RANGES`. Integral floats (``1e5``) pass as
    integers. Never builds a model."""
    params = inspect.signature(algo_cls.__init__).parameters
    valid = sorted(k for k in params if k not in _SET_BY_TRAIN)
    for k, v in hp.items():
        if k not in valid:
            raise ValueError(f"{k} is not a valid key for {algo_cls.__name__}; valid keys: {', '.join(valid)}")
        if k == "train_freq" and isinstance(v, (list, tuple)):
            continue  # the zoo's [1, "episode"]
        if k == "policy_kwargs" or k.endswith("_kwargs"):
            if not isinstance(v, dict):
                raise ValueError(f"{k}={v!r} is invalid; valid type: mapping")
            continue
        _check_value(k, v, params[k].default)


def _yaml_note(v) -> str:
    """``; a number, not a string (YAML 1.1 ...)`` for a string that reads as a number (``learning_rate: 1e-4``
    in a YAML file is the string "1e-4": "valid type: number" alone looked wrong to whoever wrote a number)."""
    try:
        float(v)
    except (TypeError, ValueError):
        return ""
    return "; " + YAML_NUMBER_NOTE if isinstance(v, str) else ""


def _check_value(k: str, v, default) -> None:
    """One hyperparameter against its default's type and :data:`HP_RANGES`."""
    key = k
    if isinstance(default, bool) or k.startswith("use_") or k.startswith("normalize") or k.startswith("optimize"):
        if not isinstance(v, bool):
            raise ValueError(f"{key}={v!r} is invalid; valid type: true or false")
        return
    if isinstance(v, str) and isinstance(default, str) and (v == "auto" or v.startswith("auto_")):
        return  # SAC's ent_coef / target_entropy "auto", "auto_0.1"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        if default is None and v is None:
            return
        kind = "integer" if isinstance(default, int) or k in HP_RANGES and HP_RANGES[k].integer else "number"
        raise ValueError(f"{key}={v!r} is invalid; valid type: {kind}" + _yaml_note(v))
    rng = HP_RANGES.get(k, Range(-float("inf"), float("inf")) if not isinstance(default, int) else
                        Range(-_BIG, _BIG, integer=True))
    if not rng.contains(v):
        raise ValueError(f"{key}={v!r} is invalid; valid range: {rng.text() if rng.hi < float('inf') else 'finite'}")
