"""The shipped PPO policies load for inference from the zip's state dict (issue 22): the same actor as
stable-baselines3's model gives, without importing stable-baselines3 or building an optimiser."""

import subprocess
import sys

import numpy as np
import pytest

from policies.rl import PRETRAINED, PRETRAINED_LAGRANGIAN, load_meta

pytest.importorskip("torch")


@pytest.mark.parametrize("path", [PRETRAINED, PRETRAINED_LAGRANGIAN], ids=lambda p: p.stem)
def test_state_dict_actor_is_sb3s_actor(path):
    sb3 = pytest.importorskip("stable_baselines3")
    from policies.inference import export_actor, load_ppo_actor
    fast = load_ppo_actor(path, load_meta(path))
    ref = export_actor(sb3.PPO.load(str(path), device="cpu"))
    assert fast is not None and ref is not None
    obs = np.random.default_rng(0).uniform(-1.5, 1.5, (256, fast.layers[0][0].shape[0])).astype(np.float32)
    np.testing.assert_array_equal(fast.forward(obs), ref.forward(obs))   # same float32 weights, same ops
    np.testing.assert_array_equal(fast.act(obs), ref.act(obs))
    assert np.all(np.abs(fast.act(obs)) <= 1.0) and np.any(np.abs(fast.forward(obs)) > 0)


def test_rl_policy_acts_without_importing_stable_baselines3():
    code = ("import sys, numpy as np, policies\n"
            "from mission_sim.contract import PolicyContext\n"
            "p = policies.make('rl', PolicyContext())\n"
            "p.reset(1)\n"
            "d = float(np.asarray(p.act(np.zeros((1, 8)))).reshape(-1)[0])\n"
            "assert 0.0 <= d <= 1.0, d\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'stable_baselines3'))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def test_numpy_state_dict_reader_is_torch_load_bit_for_bit_and_refuses_other_objects():
    """policies.inference.read_state_dict (no torch import) gives torch.load's tensors for every shipped zip;
    a pickle with anything but plain tensors is refused (None: the caller falls back to torch.load)."""
    import glob
    import io
    import zipfile

    import torch

    from policies.inference import read_state_dict
    zips = sorted(glob.glob(str(PRETRAINED.parent / "*.zip")))
    assert len(zips) >= 3
    for path in zips:
        blob = zipfile.ZipFile(path).read("policy.pth")
        ours, ref = read_state_dict(blob), torch.load(io.BytesIO(blob), map_location="cpu", weights_only=True)
        assert ours is not None and list(ours) == list(ref)
        for k, t in ref.items():
            assert ours[k].dtype == t.numpy().dtype and ours[k].shape == tuple(t.shape)
            assert np.array_equal(ours[k], t.numpy()), (path, k)
    buf = io.BytesIO()
    torch.save({"w": torch.ones(2), "step": torch.nn.Linear(1, 1)}, buf)   # a module: not a plain state dict
    assert read_state_dict(buf.getvalue()) is None
    assert read_state_dict(b"not a zip") is None
