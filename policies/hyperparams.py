"""Hyperparameters from a file in rl-baselines3-zoo style (YAML or JSON).

Accepted shapes: the algorithm's keyword arguments at top level, or nested under one key (the
env id, e.g. ``dronewpt/SbarCharging-v0:``, as in the zoo's ``hyperparams/ppo.yml``). Zoo keys
that are not model arguments are taken out: ``n_timesteps`` and ``n_envs`` (returned apart, the
caller's explicit values win), ``policy`` (must be ``MlpPolicy``), ``normalize`` (``train`` always
normalises observations). ``policy_kwargs`` may be a mapping or the zoo's string
``"dict(net_arch=[64, 64], log_std_init=-1.5)"`` (keyword literals only; parsed with ``ast``,
never evaluated). Schedules such as ``lin_3e-4`` are not supported (an error names the value).
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

__all__ = ["load_hyperparams", "parse_policy_kwargs"]

_ZOO_ONLY = ("n_timesteps", "n_envs", "policy", "normalize")


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
    text = path.read_text()
    if path.suffix.lower() == ".json":
        return json.loads(text)
    if path.suffix.lower() in (".yml", ".yaml"):
        import yaml
        return yaml.safe_load(text)
    raise ValueError(f"hyperparams file {str(path)!r} is invalid; valid suffixes: .yml, .yaml, .json")


def load_hyperparams(path) -> tuple[dict, dict]:
    """``(model kwargs, zoo extras)`` from a YAML / JSON file; extras holds ``n_timesteps`` / ``n_envs``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"hyperparams file {str(path)!r} does not exist")
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
            extras[k] = int(float(extras[k]))
    return hp, extras
