"""Loose ends left by the evening's sessions (2026-11-27 night; docs/changes.md, "2026-11-27 night"): each test fails
on the branch's start (f378fbc) and passes here; its docstring says what it checks."""

from __future__ import annotations

import math
import re

import pytest

from _cli_helpers import one_error_line


# ------------------------------------------------------------------ 1. --history: the contract's rule and words
def test_train_history_is_checked_by_the_contracts_rule(capsys, tmp_path, monkeypatch):
    """``dronewpt train --history`` had its own copy of the rule (``1 <= K <= MAX_HISTORY``, "valid range: 1..32");
    now :func:`mission_sim.contract.check_history` decides and words it (a changed range moves both)."""
    from mission_sim import contract
    from mission_sim.validation import Range
    out = tmp_path / "o"
    assert one_error_line(capsys, ["train", "--algo", "ppo", "--timesteps", "1", "--out", str(out), "--history",
                                   "40"]) == "dronewpt train: error: --history 40 is invalid; valid range: integer 1..32"
    monkeypatch.setattr(contract, "HISTORY_RANGE", Range(1, 4, integer=True))
    assert one_error_line(capsys, ["train", "--algo", "ppo", "--timesteps", "1", "--out", str(out), "--history",
                                   "33"]) == "dronewpt train: error: --history 33 is invalid; valid range: integer 1..4"
    with pytest.raises(ValueError, match=r"^history=33 is invalid; valid range: integer 1\.\.4$"):
        contract.check_history(33)
    assert not out.exists()


# ------------------------------------------------------------------ 2. coupling --dz below the pad: the library's rule
def test_a_receiver_below_the_pad_is_refused_by_the_library_too(capsys):
    """``dronewpt coupling`` refused a negative ``--dz`` by its own check; now
    ``CouplingModel.check_clearance(..., above_pad=True)`` holds that rule and its words (the command calls it), so
    Python refuses it too, with the command's message (beside the pad as over it); without ``above_pad`` the rule is
    the touching band alone, as before."""
    import math

    from wpt_receiver.coupling import default_coupling
    m = default_coupling()
    for dx in (0.0, 2.0):
        with pytest.raises(ValueError, match=r"^dz_m=-0.5 is invalid; valid range: > 0.0034 m \(the coils would "
                                             r"touch\)$"):
            m.check_clearance(dx, 0.0, -0.5, above_pad=True)
        assert one_error_line(capsys, ["coupling", "--dz", "-0.5", "--dx", str(dx)]) == (
            "dronewpt coupling: error: --dz -0.5 is invalid; valid range: > 0.0034 m (the coils would touch)")
    gap = float(m.clearance_m(math.radians(10)))
    with pytest.raises(ValueError, match=rf"^dz_m=-0.001 is invalid; valid range: > {gap:.4g} m"):
        m.check_clearance(0.0, 0.0, -0.001, math.radians(10), above_pad=True)
    with pytest.raises(ValueError, match=r"^dz_m=-0.01 is invalid"):   # the first bad pose of an array
        m.check_clearance(0.0, 0.0, [0.2, -0.01, 0.001], above_pad=True)
    m.check_clearance(0.0, 0.0, -0.5)   # the touching rule alone: apart
    m.check_clearance(2.0, 0.0, 0.001, above_pad=True)   # above the plane, beside the pad: computed


# ------------------------------------------------------------------ 3. float_arg is range_arg of a Range
@pytest.mark.parametrize("kwargs, rng", [
    ({"positive": True, "lo": 1e-7, "hi": 1e-3}, (1e-7, 1e-3, False, False, "[1e-07, 0.001]")),
    ({"positive": True, "hi": 1.0}, (0.0, 1.0, True, False, "(0, 1]")),
    ({"positive": True}, (0.0, float("inf"), True, True, "(0, inf)")),
    ({}, (-float("inf"), float("inf"), True, True, "finite"))])
def test_float_arg_is_range_arg_of_its_range(kwargs, rng, monkeypatch):
    """``cli.common.float_arg`` had its own copy of ``range_arg``'s float branch (parse, "is not a number", the range
    check and its text); now it builds the :class:`~mission_sim.validation.Range` and calls ``range_arg``, whose text
    says ``finite`` for every real number. The messages are the old ones (308 option/text pairs compared when
    changed)."""
    import argparse

    from mission_sim.cli import common
    seen = []
    real = common.range_arg
    monkeypatch.setattr(common, "range_arg", lambda name, r: seen.append(r) or real(name, r))
    conv = common.float_arg("x", **kwargs)
    lo, hi, lo_open, hi_open, text = rng
    assert [(r.lo, r.hi, r.lo_open, r.hi_open, r.text()) for r in seen] == [(lo, hi, lo_open, hi_open, text)]
    with pytest.raises(argparse.ArgumentTypeError, match=rf"^x='nan' is invalid; valid range: {re.escape(text)}$"):
        conv("nan")
    with pytest.raises(argparse.ArgumentTypeError, match=r"^x='a' is not a number$"):
        conv("a")


@pytest.mark.parametrize("lo, hi, text", [(-5.0, float("inf"), "(0, inf)"), (-5.0, 10.0, "(0, 10]"),
                                          (0.0, 10.0, "(0, 10]")])
def test_a_positive_float_arg_is_above_zero_whatever_lo(lo, hi, text):
    """``float_arg(positive=True)`` with ``lo < 0`` took ``(lo, hi]`` (negative values and 0) once it became
    ``range_arg`` of a ``Range(lo, ...)``; main, and the docstring, refuse them: "> 0 if positive" whatever ``lo``."""
    import argparse

    from mission_sim.cli.common import float_arg
    conv = float_arg("x", positive=True, lo=lo, hi=hi)
    for bad in ("-1", "0", "-5"):
        with pytest.raises(argparse.ArgumentTypeError, match=rf"^x='{bad}' is invalid; valid range: {re.escape(text)}$"):
            conv(bad)
    assert conv("1e-9") == 1e-9 and conv("10") == 10.0


# ------------------------------------------------------------------ 4. replay's summary file: one spelling each
@pytest.mark.parametrize("pads", [True, False])
def test_replays_summary_file_is_spelt_once(capsys, tmp_path, monkeypatch, pads):
    """``replay`` / ``replay --pads`` spelt ``replay_summary.json`` / ``refly_summary.json`` three times each (cleared,
    written, listed); now one constant each (``cli.mavlink.REPLAY_SUMMARY``, ``cli.refly.REFLY_SUMMARY``): renamed
    there, the file is cleared, written and listed under the new name, nothing under the old."""
    import json
    from pathlib import Path

    from mission_sim.cli import main, mavlink, refly
    data = Path(__file__).parent / "data"
    name = "renamed_summary.json"
    monkeypatch.setattr(refly if pads else mavlink, "REFLY_SUMMARY" if pads else "REPLAY_SUMMARY", name)
    out = tmp_path / "o"
    out.mkdir()
    (out / name).write_text("stale")   # a former run's: cleared before the run, then written last
    argv = ["replay", str(data / "flightlogs" / "dronekit-python_flight.tlog"), "--window", "440,620", "--out", str(out),
            "--no-plot", "--no-progress"]
    assert main(argv + (["--pads", str(data / "missions" / "dronekit_flight_pads.csv")] if pads else [])) == 0
    wrote = [ln.removeprefix("wrote ") for ln in capsys.readouterr().out.splitlines() if ln.startswith("wrote ")]
    assert wrote[-1] == str(out / name)
    assert "final_soc_refly" in json.loads((out / name).read_text()) if pads else "final_soc" in json.loads(
        (out / name).read_text())
    assert not (out / "refly_summary.json").exists() and not (out / "replay_summary.json").exists()


# ------------------------------------------------------------------ 5. an unpickled env's kernels: one lookup
@pytest.mark.parametrize("link", ["envelope", "modal"])
@pytest.mark.parametrize("compiled", [True, False])
def test_an_unpickled_envs_kernels_come_from_its_modules_kernel_function(link, compiled, monkeypatch):
    """``envs.core.kernel_from_ref`` repeated ``kernel_function``'s lookup (the module's name, then the dispatcher or
    its ``py_func``); now it calls the module's own ``kernel_function``: swapped there, an unpickled env's step and
    duty map are what it gives."""
    import pickle

    from envs import modal_step, vector_kernel
    from envs.vector import SbarChargingVectorEnv
    env = SbarChargingVectorEnv(2, config={"link_model": link}, compiled=compiled)
    state = pickle.dumps(env)
    asked = []
    for mod in (vector_kernel, modal_step):
        real = mod.kernel_function
        monkeypatch.setattr(mod, "kernel_function", lambda name, c=True, real=real, mod=mod:
                            asked.append((mod.__name__, name, c)) or real(name, c))
    twin = pickle.loads(state)
    step = "envs.modal_step" if link == "modal" else "envs.vector_kernel"
    assert (step, "env_step", compiled) in asked
    assert ("envs.vector_kernel", "duty_kernel", True) in asked if compiled else True
    assert twin.parts.plant.kernel is env.parts.plant.kernel


# ------------------------------------------------------------------ 6. zoh_discretise: the slow pole once
def test_the_real_pole_branch_takes_zoh_discretises_slow_pole(monkeypatch):
    """``zoh_discretise`` computed a stiff link's slow pole ``det / (s - q)`` three times (for ``Ad``, for the
    branch's test and inside ``_real_pole_phi``); now once, handed to ``_real_pole_phi``: the branch gets that array,
    bit for bit (its results were compared with the former function's to the bit when changed)."""
    import math

    import numpy as np

    from wpt_receiver import LinkParams, envelope
    p = LinkParams(l1_h=1.0, l2_h=1e-9, lm_h=1e-3 * math.sqrt(1e-9), r1_ohm=1e-6, r2_ohm=100.0, f_hz=1e4)
    a, b = envelope.state_matrices(p)
    seen = []
    real = envelope._real_pole_phi
    monkeypatch.setattr(envelope, "_real_pole_phi", lambda *args: seen.append(args) or real(*args))
    envelope.zoh_discretise(a, b, 1e-7)
    assert len(seen) == 1
    aa, l2, l1, _ = seen[0]
    det = aa[:, 0, 0] * aa[:, 1, 1] - aa[:, 0, 1] * aa[:, 1, 0]
    assert np.array_equal(l1, det / l2) and abs(l1[0]) < abs(l2[0])   # the slow pole, as computed for Ad


# ------------------------------------------------------------------ 7. model_based_online: no input checks per step
def test_the_online_policys_control_step_skips_steady_states_checks(monkeypatch):
    """``model_based_online`` called the public ``steady_state`` every control step, whose input checks (V2 finite, Lm
    in [0, sqrt(L1 L2))) cost ~2 us each; now its step calls the public, unchecked ``envelope.steady_state_unchecked``
    (its Lm was checked by ``LinkParams`` when its controller was built, its V2* comes from observations it checks
    finite): the checks run at the builds only, and the duties are the public function's to the bit."""
    import numpy as np

    import policies
    from mission_sim.contract import OBS_DIM
    from wpt_receiver import envelope
    calls = {"v2": 0, "lm": 0}
    for key, name in (("v2", "check_v2"), ("lm", "check_lm")):
        real = getattr(envelope, name)
        monkeypatch.setattr(envelope, name, lambda *a, real=real, key=key, **k: calls.__setitem__(key, calls[key] + 1)
                            or real(*a, **k))
    rng = np.random.default_rng(7)
    obs = np.clip(rng.normal(0.0, 0.3, (200, 3, OBS_DIM)), -1, 1)
    pol = policies.make("model_based_online")
    pol.reset(3)
    duties, quiet = [], 0
    for o in obs:
        before, built = dict(calls), pol.rebuilds
        duties.append(pol.act(o))
        if pol.rebuilds == built:   # a step without a controller build: no check of steady_state's ran
            assert calls == before
            quiet += 1
    assert quiet > 100 and calls["v2"] > 0   # (the builds checked theirs)
    duties = np.array(duties)
    # the same steps on the public, checked steady_state: the same bits
    monkeypatch.setattr(policies.online, "steady_state_unchecked",
                        lambda p, v2, lm, v1: envelope.steady_state(p, v2, lm_h=lm, v1_v=v1))
    ref = policies.make("model_based_online")
    ref.reset(3)
    assert np.array_equal(np.array([ref.act(o) for o in obs]), duties)
    assert "steady_state_unchecked" in envelope.__all__ and "unchecked" not in envelope.steady_state.__name__


@pytest.mark.parametrize("field, receiver", [("battery_v", 0), ("charge_cmd_a", 1), ("i2_amp_a", 2),
                                             ("last_d_short", 0)])
def test_the_online_policy_refuses_a_non_finite_observation_where_it_arrives(field, receiver):
    """A NaN ``battery_v`` gave NaN duties for every later step (the estimator and the controllers poisoned until
    ``reset``), a NaN ``charge_cmd_a`` a NaN duty and, the next step, ``v2_v=nan is invalid`` from the bumpless
    rebuild (an internal value); now any non-finite field the controller reads is refused at its step, naming the
    field, the receiver and the range, before any state moves: the steps after it are those of a run without it."""
    import numpy as np

    import policies
    from mission_sim.contract import OBS_DIM, OBS_INDEX
    n = 1 if receiver == 0 and field != "battery_v" else 3
    obs = np.clip(np.random.default_rng(3).normal(0.0, 0.3, (60, n, OBS_DIM)), -1, 1)
    clean, hit = policies.make("model_based_online"), policies.make("model_based_online")
    clean.reset(n)
    hit.reset(n)
    want = np.array([clean.act(o) for o in obs])
    got = [hit.act(o) for o in obs[:20]]
    for bad in (np.nan, np.inf):
        o = obs[20].copy()
        o[receiver, OBS_INDEX[field]] = bad
        with pytest.raises(ValueError, match=rf"^observation {field}={bad!r} \(receiver {receiver}\) is invalid; valid "
                                             r"range: finite \(normalised: -1\.\.1 is [-0-9.]+\.\.[0-9.]+( [A-Za-z]+)?\)$"):
            hit.act(o)
    got += [hit.act(o) for o in obs[20:]]
    assert np.array_equal(np.array(got), want) and np.isfinite(want).all()
    # review of the merge: the message named a range, [-1, 1], that is not checked; 5.0 (normalised) is taken
    o = obs[0].copy()
    o[receiver, OBS_INDEX[field]] = 5.0
    clean.reset(n)
    assert np.isfinite(clean.act(o)).all()


# ------------------------------------------------------------------ 8. the vector env: render, episode length
def test_the_vector_env_renders_none_with_gymnasiums_warning():
    """``render()`` on the vector env raised gymnasium's ``NotImplementedError``; a vector env made with
    ``render_mode=None`` returns None with a warning (gymnasium's ``CartPoleVectorEnv``), as the single env does."""
    import warnings

    import gymnasium

    import envs
    venv = gymnasium.make_vec(envs.ENV_ID, num_envs=2, vectorization_mode="vector_entry_point")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert venv.render() is None
    assert any("render a single env" in str(w.message) for w in caught)


@pytest.mark.parametrize("link", ["envelope", "modal"])
def test_make_vec_takes_max_episode_steps_as_make_does(link):
    """``gymnasium.make_vec(ID, ..., max_episode_steps=N)`` hands N to the vector env, which refused it (TypeError:
    an unexpected keyword); now it truncates each window after ``min(N, n_steps)`` steps, as the single env's
    ``TimeLimit`` does, the steps before the cut the same bits as without it, and autoresets after."""
    import gymnasium
    import numpy as np

    import envs
    kw = dict(num_envs=3, vectorization_mode="vector_entry_point", config={"link_model": link})
    cut, full = gymnasium.make_vec(envs.ENV_ID, max_episode_steps=5, **kw), gymnasium.make_vec(envs.ENV_ID, **kw)
    a = np.zeros((3, 1))
    (o1, _), (o2, _) = cut.reset(seed=4), full.reset(seed=4)
    assert np.array_equal(o1, o2)
    for k in range(1, 6):
        r1, r2 = cut.step(a), full.step(a)
        for x, y in zip(r1[:3], r2[:3]):
            assert np.array_equal(x, y)
        assert r1[3].all() == (k == 5) and not r2[3].any()
    o1 = cut.step(a)[0]   # the autoreset: a new window's first observation
    assert not np.array_equal(o1, full.step(a)[0])
    assert cut.unwrapped.max_episode_steps == 5 and full.unwrapped.max_episode_steps is None
    long = gymnasium.make_vec(envs.ENV_ID, max_episode_steps=10_000, **kw)   # beyond n_steps: n_steps decides
    long.reset(seed=4)
    assert [bool(long.step(a)[3].all()) for _ in range(300)] == [False] * 299 + [True]
    for bad in (0, -2, True):
        with pytest.raises(ValueError, match=rf"^max_episode_steps={bad!r} is invalid; valid range: integer >= 1 \(or "
                                             r"None / -1: n_steps\)$"):
            gymnasium.make_vec(envs.ENV_ID, max_episode_steps=bad, **kw)


def test_max_episode_steps_minus_one_cuts_nothing_as_make_does():
    """``gymnasium.make(ID, max_episode_steps=-1)`` applies no ``TimeLimit``; ``make_vec(..., max_episode_steps=-1)``
    said ``max_episode_steps=-1 is invalid``: now -1 (as None) cuts nothing, the window runs its ``n_steps``."""
    import gymnasium
    import numpy as np

    import envs
    single = gymnasium.make(envs.ENV_ID, max_episode_steps=-1)
    assert "TimeLimit" not in str(single)
    venv = gymnasium.make_vec(envs.ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=-1)
    assert venv.unwrapped.max_episode_steps is None
    venv.reset(seed=1)
    a = np.zeros((2, 1))
    assert [bool(venv.step(a)[3].all()) for _ in range(300)] == [False] * 299 + [True]


# ------------------------------------------------------------------ 9. the rectifier's rating beside the peak
def test_the_devices_current_rating_is_the_lowest_of_the_parts_carrying_i2(monkeypatch):
    """:func:`wpt_receiver.devices.current_rating`: the lowest ``rating_a`` of the preset's rectifier diode leg and
    switch; it and :func:`~wpt_receiver.devices.preset` look the preset up in one place (``_preset_row``: "ideal",
    an unknown name's message)."""
    from wpt_receiver import devices
    assert devices.current_rating("schottky") == (15.0, "30CTT045", "rectifier diode")
    assert devices.current_rating("sic") == (50.0, "C5D50065D", "rectifier diode")
    assert devices.current_rating("ideal") is None and devices.preset("ideal") is devices.IDEAL
    for f in (devices.current_rating, devices.preset):
        with pytest.raises(ValueError, match=r"^device preset 'nope' is unknown; valid: ideal, schottky, sic"):
            f("nope")
    monkeypatch.setattr(devices, "_preset_row", lambda name: None)   # the one lookup: both follow it
    assert devices.current_rating("schottky") is None and devices.preset("schottky") is devices.IDEAL


def test_a_missions_summary_reports_the_rectifiers_rating_beside_the_peak(capsys, tmp_path, monkeypatch):
    """docs/mission.md's gust example peaked at 19.5 A (one 100 us step at a pad's switch-off, a modelling artefact
    fixed 2026-11-28: 14.74 A now), above the 15 A continuous rating of the default devices' rectifier diode: no warning (the review: it disagreed with ``dronewpt
    sizing``'s rule and fired on every shipped run), a result: ``summary.json``'s ``rectifier_rating_a`` /
    ``rectifier_rating_part`` and one line of the table, with the sizing rule's margin from
    ``wpt_receiver.sizing.SizingRules`` (a changed margin moves the line). Ideal devices: null, no line."""
    import json

    from mission_sim.cli import main
    from wpt_receiver.sizing import SizingRules
    gust = ["mission", "--set", "wind.gust_sigma_m_s=3", "--set", "pads.0.hover_time_s=30", "--no-plot",
            "--no-progress", "--out", str(tmp_path / "g")]
    monkeypatch.setattr(SizingRules, "margin", 1.5)
    assert main(gust) == 0
    cap = capsys.readouterr()
    s = json.loads((tmp_path / "g" / "summary.json").read_text())
    assert cap.err == "" and s["peak_i2_a"] > 10.0
    assert (s["rectifier_rating_a"], s["rectifier_rating_part"]) == (15.0, "30CTT045")
    # (later 2026-11-28: summary.json's rectifier_required_a, the rule's rating for the peak, at the patched margin)
    assert s["rectifier_required_a"] == 1.5 * s["peak_i2_a"]
    line = [x for x in cap.out.splitlines() if x.startswith("rectifier current rating")]
    # (2026-11-28: the part below the rule ends the row in a note with the shortfall, at the patched margin; "note",
    # not "warning": the rule compares a millisecond peak with the part's average rating, it is conservative)
    short = 1.5 * s["peak_i2_a"] - 15.0
    n_legs = math.ceil(1.5 * s["peak_i2_a"] / 15.0)
    assert len(line) == 1 and line[0].split(None, 4)[3:] == [
        "15", f"A continuous, 30CTT045 (peak I2 {s['peak_i2_a']:.2f} A; dronewpt sizing requires a rating >= 1.5 x "
              f"peak = {1.5 * s['peak_i2_a']:.2f} A); note: {short:.2f} A ({100 * short / 15:.1f} %) below dronewpt "
              "sizing's rule (1.5 x peak against the part's average rating, conservative): dronewpt sizing --source "
              f"mission parallels {n_legs} legs"], line
    assert "warning" not in cap.out
    assert main(["mission", "--set", "link.devices=ideal", "--no-plot", "--format", "json", "--no-progress", "--out",
                 str(tmp_path / "i")]) == 0
    cap = capsys.readouterr()
    s = json.loads(cap.out)
    assert cap.err == "" and s["rectifier_rating_a"] is None and s["rectifier_rating_part"] is None
    assert s["rectifier_required_a"] == SizingRules.margin * s["peak_i2_a"]
