"""Fast deterministic inference of stable-baselines3 policies: the actor exported to numpy.

``model.predict`` costs 1-1.5 ms a call (mode switching, tensor conversion, checks), which made
an RL policy ~20x slower than the classical ones in the mission loop. The deterministic action
of an MLP policy is a few small matrix products, so :func:`export_actor` copies the actor's
weights into float32 numpy arrays once and :class:`NumpyActor` evaluates

* PPO / A2C (``ActorCriticPolicy``): ``action_net(policy_net(obs))`` = the Gaussian's mean,
  clipped to the action box (``predict`` clips; no squashing), or the arg-max logit for a
  discrete action space,
* SAC (``SACPolicy``): ``tanh(mu(latent_pi(obs)))`` rescaled to the action box,
* DQN (``DQNPolicy``): the arg-max of ``q_net(obs)``,

with the same layers and activations (float32, like torch). :func:`load_ppo_actor` builds the same
actor for a plain PPO model straight from the zip's ``policy.pth`` state dict (torch only to read
it, and only for a layout :func:`read_state_dict` does not know): no torch, no stable-baselines3
import, no model, no optimiser. Results agree with
``predict(deterministic=True)`` to float32 round-off (tests/test_rl_inference.py). Anything else
(image or dict observations, custom feature extractors, gSDE, unknown activations) is not
exported: :func:`export_actor` returns ``None`` and the caller keeps ``predict``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NumpyActor", "export_actor", "load_ppo_actor", "read_state_dict"]

_ACTIVATIONS = {
    "Tanh": np.tanh,
    "ReLU": lambda h: np.maximum(h, np.float32(0.0)),
    "Identity": lambda h: h,
}


class NumpyActor:
    """A feed-forward actor as numpy layers: ``act(obs (n, d)) -> actions (n, action_dim)``.

    ``layers`` is a list of ``(W (out, in), b (out,))`` or activation callables applied in order;
    ``head`` maps the last output to actions: ``"clip"`` (to ``[low, high]``), ``"tanh_scale"``
    (tanh then rescale from [-1, 1] to ``[low, high]``) or ``"argmax"`` (discrete).
    """

    def __init__(self, layers: list, head: str, low=None, high=None):
        if head not in ("clip", "tanh_scale", "argmax"):
            raise ValueError(f"head={head!r} is invalid; valid values: clip, tanh_scale, argmax")
        self.layers = [(np.ascontiguousarray(np.asarray(layer[0], dtype=np.float32).T), np.asarray(layer[1], dtype=np.float32))
                       if isinstance(layer, tuple) else layer for layer in layers]   # (W.T, b): h @ W.T + b
        self.head = head
        self.low = None if low is None else np.asarray(low, dtype=np.float32)
        self.high = None if high is None else np.asarray(high, dtype=np.float32)

    def forward(self, obs) -> np.ndarray:
        """The network's raw output (n, out) in float32."""
        h = np.asarray(obs, dtype=np.float32)
        if h.ndim == 1:
            h = h[None, :]
        for layer in self.layers:
            h = h @ layer[0] + layer[1] if isinstance(layer, tuple) else layer(h)
        return h

    def act(self, obs) -> np.ndarray:
        """Deterministic actions (n, action_dim) (``argmax`` head: (n,) integers)."""
        out = self.forward(obs)
        if self.head == "argmax":
            return np.argmax(out, axis=1)
        if self.head == "tanh_scale":
            out = self.low + (0.5 * (np.tanh(out) + 1.0)) * (self.high - self.low)
            return out
        return np.minimum(np.maximum(out, self.low), self.high)   # = np.clip, faster on one row


def _sequential_layers(seq) -> list | None:
    """A torch ``Sequential`` (or single ``Linear``/empty) as numpy layers; ``None`` if unsupported."""
    import torch.nn as nn

    mods = list(seq) if isinstance(seq, nn.Sequential) else [seq]
    out = []
    for m in mods:
        if isinstance(m, nn.Linear):
            w = m.weight.detach().cpu().numpy().astype(np.float32)
            b = (m.bias.detach().cpu().numpy() if m.bias is not None else np.zeros(w.shape[0])).astype(np.float32)
            out.append((w, b))
        elif type(m).__name__ in _ACTIVATIONS:
            out.append(_ACTIVATIONS[type(m).__name__])
        else:
            return None
    return out


def _flat_box_obs(policy, extractor) -> bool:
    """Flat Box observations through SB3's ``FlattenExtractor`` (features = observation)."""
    from gymnasium import spaces
    from stable_baselines3.common.torch_layers import FlattenExtractor

    return (isinstance(policy.observation_space, spaces.Box) and len(policy.observation_space.shape) == 1
            and isinstance(extractor, FlattenExtractor))


def _export_actor_critic(policy):
    from gymnasium import spaces

    if getattr(policy, "use_sde", False) or getattr(policy, "squash_output", False):
        return None
    body = _sequential_layers(policy.mlp_extractor.policy_net)
    head = _sequential_layers(policy.action_net)
    if body is None or head is None:
        return None
    space = policy.action_space
    if isinstance(space, spaces.Discrete):
        return NumpyActor(body + head, "argmax")
    if isinstance(space, spaces.Box):
        return NumpyActor(body + head, "clip", space.low, space.high)
    return None


def _export_sac(policy):
    actor = policy.actor
    if getattr(actor, "use_sde", False) or not _flat_box_obs(policy, actor.features_extractor):
        return None
    body, mu = _sequential_layers(actor.latent_pi), _sequential_layers(actor.mu)
    if body is None or mu is None:
        return None
    return NumpyActor(body + mu, "tanh_scale", policy.action_space.low, policy.action_space.high)


def _export_dqn(policy):
    qnet = policy.q_net
    if not _flat_box_obs(policy, qnet.features_extractor):
        return None
    layers = _sequential_layers(qnet.q_net)
    return None if layers is None else NumpyActor(layers, "argmax")


def export_actor(model) -> NumpyActor | None:
    """The deterministic actor of an SB3 model (PPO, A2C, SAC, DQN; MLP on flat Box observations)
    as a :class:`NumpyActor`, or ``None`` when the architecture is not covered (use ``predict``)."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    policy = model.policy
    if isinstance(policy, ActorCriticPolicy):
        extractor = getattr(policy, "pi_features_extractor", policy.features_extractor)
        return _export_actor_critic(policy) if _flat_box_obs(policy, extractor) else None
    if hasattr(policy, "actor") and hasattr(policy.actor, "latent_pi"):   # SAC (TD3's actor: predict)
        return _export_sac(policy)
    if hasattr(policy, "q_net") and hasattr(policy.q_net, "q_net"):
        return _export_dqn(policy)
    return None


def _space_bounds(space: dict):
    """``(low, high)`` float32 arrays of a Box serialised in an SB3 zip's ``data`` JSON (``'[-1.]'``)."""
    def parse(text):
        return np.array(str(text).strip("[]").split(), dtype=np.float32)
    return parse(space["low"]), parse(space["high"])


def load_ppo_actor(path, meta: dict) -> NumpyActor | None:
    """The deterministic actor of a PPO model zip written by ``dronewpt train`` (MLP ``net_arch`` of
    SB3's default Tanh, continuous flat Box spaces, no gSDE: the shipped models), read from the
    zip's ``policy.pth`` state dict (:func:`read_state_dict`, no torch; ``torch.load(weights_only=True)``
    for a layout it does not know); the same numbers as
    :func:`export_actor` of ``PPO.load`` (tests). ``None`` for anything else (the caller loads the
    model with SB3)."""
    import io
    import json
    import zipfile

    kwargs = meta.get("policy_kwargs") or {}
    arch = kwargs.get("net_arch", [64, 64])
    if meta.get("algo") != "ppo" or meta.get("discrete") or set(kwargs) - {"net_arch", "log_std_init"} \
            or not (isinstance(arch, list) and all(isinstance(n, int) for n in arch)):
        return None
    with zipfile.ZipFile(path) as z:
        data = json.loads(z.read("data"))
        if data.get("use_sde") or "Box" not in str(data.get("action_space", {}).get(":type:")):
            return None
        blob = z.read("policy.pth")
    state = read_state_dict(blob)
    if state is None:   # a layout the numpy reader does not know: torch reads it
        import torch
        state = {k: v.numpy() for k, v in torch.load(io.BytesIO(blob), map_location="cpu", weights_only=True).items()}
    layers = []
    for i in range(len(arch)):
        w, b = state.get(f"mlp_extractor.policy_net.{2 * i}.weight"), state.get(f"mlp_extractor.policy_net.{2 * i}.bias")
        if w is None or b is None:
            return None
        layers += [(w, b), _ACTIVATIONS["Tanh"]]
    if f"mlp_extractor.policy_net.{2 * len(arch)}.weight" in state or "action_net.weight" not in state:
        return None
    layers.append((state["action_net.weight"], state["action_net.bias"]))
    return NumpyActor(layers, "clip", *_space_bounds(data["action_space"]))


#: torch storage classes of a state dict -> numpy dtypes (what ``read_state_dict`` accepts)
_STORAGE_DTYPES = {"FloatStorage": np.float32, "DoubleStorage": np.float64, "HalfStorage": np.float16,
                   "LongStorage": np.int64, "IntStorage": np.int32, "ShortStorage": np.int16,
                   "CharStorage": np.int8, "ByteStorage": np.uint8, "BoolStorage": np.bool_}


def _rebuild_tensor(storage, offset, size, stride, requires_grad=False, hooks=None, metadata=None):
    """numpy copy of ``torch._utils._rebuild_tensor_v2``: ``size``/``stride`` in elements into ``storage``."""
    item = storage.itemsize
    view = np.lib.stride_tricks.as_strided(storage[offset:], shape=tuple(size), strides=tuple(s * item for s in stride))
    return np.array(view)


def read_state_dict(blob: bytes) -> dict | None:
    """A torch state dict (``torch.save`` zip format, little-endian, tensors only) as ``{name: numpy
    array}`` without importing torch (~1-2 s of import): a restricted unpickler of the archive's
    ``data.pkl`` that knows ``OrderedDict``, ``torch._utils._rebuild_tensor_v2`` and the typed storages
    of :data:`_STORAGE_DTYPES`, reading each storage from ``data/<key>``. ``None`` for anything else
    (the caller uses ``torch.load``); same bytes as torch's tensors (tests/test_rl_lazy_load.py)."""
    import collections
    import io
    import pickle
    import zipfile

    try:
        with zipfile.ZipFile(io.BytesIO(blob)) as z:
            names = z.namelist()
            pkl = next((n for n in names if n.endswith("/data.pkl")), None)
            if pkl is None:
                return None
            root = pkl[:-len("data.pkl")]
            if f"{root}byteorder" in names and z.read(f"{root}byteorder").strip() != b"little":
                return None

            class _Unpickler(pickle.Unpickler):
                def find_class(self, module, name):
                    if (module, name) == ("collections", "OrderedDict"):
                        return collections.OrderedDict
                    if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
                        return _rebuild_tensor
                    if module == "torch" and name in _STORAGE_DTYPES:
                        return _STORAGE_DTYPES[name]
                    raise pickle.UnpicklingError(f"{module}.{name} is not a plain tensor")

                def persistent_load(self, pid):
                    kind, dtype, key, _location, numel = pid
                    if kind != "storage":
                        raise pickle.UnpicklingError(f"persistent id {kind!r}")
                    return np.frombuffer(z.read(f"{root}data/{key}"), dtype=dtype, count=int(numel))

            state = _Unpickler(io.BytesIO(z.read(pkl))).load()
    except (pickle.UnpicklingError, KeyError, ValueError, TypeError, zipfile.BadZipFile, StopIteration):
        return None
    if not isinstance(state, dict) or not all(isinstance(v, np.ndarray) for v in state.values()):
        return None
    return dict(state)
