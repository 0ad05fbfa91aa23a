"""What a newcomer ran into on a fresh clone (2026-11-26 night; every case tried is listed in
docs/robustness.md, "A newcomer's pass"): each test here failed before its fix."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from _cli_helpers import one_error_line as _one_error_line   # exit 2, one line on stderr, no traceback

from mission_sim.cli import main

MISSIONS = Path(__file__).resolve().parent / "data" / "missions"


# ------------------------------------------------------------------ a mission in a flight log
def test_log_under_a_bin_folder_is_read_not_executed(tmp_path, capfd):
    """``--plan .../bin/flight.tlog``: the uploaded mission was read with ``mavlink_connection``, which runs
    any existing file whose path contains /bin/ as a program ("executing '...'", then
    ``[Errno 13] Permission denied``, or the file run if it was executable)."""
    from mission_sim.plans.items import uploaded_mission
    src = MISSIONS / "uavlogviewer_vtol_sitl_mission.tlog"
    (tmp_path / "bin").mkdir()
    moved = tmp_path / "bin" / src.name
    shutil.copyfile(src, moved)
    capfd.readouterr()
    a, b = uploaded_mission(src), uploaded_mission(moved)
    assert len(a.items) == 4 and a.items == b.items and a.home == b.home
    assert capfd.readouterr() == ("", "")


def test_garbage_dataflash_plan_is_one_line(tmp_path, capfd):
    """``--plan garbage.bin``: pymavlink's DataFlash reader printed one "bad header 0x... at N" line per
    corrupt byte run (4,474 lines for 5 kB of noise) before the one-line error."""
    p = tmp_path / "garbage.bin"
    p.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    assert main(["mission", "--plan", str(p), "--no-plot", "--out", str(tmp_path / "m")]) == 2
    out, err = capfd.readouterr()
    assert out == "" and err.splitlines() == [
        "dronewpt mission: error: garbage.bin: no flown track: 0 usable position(s) (GPS fix >= 3)"], err   # (no armed state read)


# ------------------------------------------------------------------ the example study
def test_subnormal_edge_current_gives_no_overflow_warning():
    """``dronewpt sweep examples/study_small.toml`` printed ``edge_losses.py:58: RuntimeWarning: overflow
    encountered in divide`` (twice, from the workers): a duty near 1 makes the switched current
    ``I2 cos(pi d / 2)`` subnormal and ``V / I`` overflows. The energy is the same (0 J for that edge)."""
    import warnings

    from wpt_receiver.edge_losses import turn_off_energy
    v, i = np.array([30.0, 30.0, 30.0]), np.array([5e-324, 0.0, 5.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        e = turn_off_energy(v, i, 2e-8, 1e-9)
    assert e[0] == 0.0 and e[1] == 0.0
    t1 = np.sqrt(2.0 * 2e-8 * 1e-9 * 30.0 / 5.0)   # the closed form of the docstring at 5 A
    u = min(t1 / 2e-8, 1.0)
    assert e[2] == 25.0 * 4e-16 * (u ** 3 / 3 - u ** 4 / 4) / 2e-9 + 0.5 * 30.0 * 5.0 * 2e-8 * (1 - u) ** 2


# ------------------------------------------------------------------ telemetry pacing
def test_telemetry_speed_and_rate_checked_before_the_simulation(tmp_path, capsys, monkeypatch):
    """``telemetry --speed 1e-300`` simulated the mission and then ended in a traceback
    (``OverflowError: timestamp out of range for platform time_t`` from time.sleep) with exit 1;
    ``--rate 1e6`` was refused only after the simulation. Both are one line before any work now."""
    import mission_sim.world.runner as runner

    def no_run(*a, **k):
        raise AssertionError("simulated before the pacing was checked")
    monkeypatch.setattr(runner, "run_mission", no_run)
    tlog = str(tmp_path / "t.tlog")
    base = ["telemetry", "--connect", "none", "--tlog", tlog]
    assert _one_error_line(capsys, base + ["--speed", "1e-300"]) == (
        "dronewpt telemetry: error: speed=1e-300 is invalid; valid range: [0.001, inf] simulated seconds per wall "
        "second (inf = as fast as possible)")
    for bad in ("0", "-1", "nan"):
        assert "valid range: [0.001, inf]" in _one_error_line(capsys, base + ["--speed", bad])
    assert _one_error_line(capsys, base + ["--rate", "1e6"]) == (
        "dronewpt telemetry: error: rate=1000000.0 is invalid; valid range: (0, 1000] Hz")
    assert not (tmp_path / "t.tlog").exists()


# ------------------------------------------------------------------ output paths inside a file
def test_paper_waveforms_inside_a_file_refused_before_simulating(tmp_path, capsys, monkeypatch):
    """``paper --model switching --waveforms FILE/w.csv`` ran the three switching runs (~20 s on a loaded
    machine) and then ended with ``[Errno 17] File exists: 'FILE'`` (no flag, no valid form)."""
    from wpt_receiver import paper

    def no_run(*a, **k):
        raise AssertionError("simulated before --waveforms was checked")
    monkeypatch.setattr(paper, "run_paper", no_run)
    (tmp_path / "plain").write_text("x")
    line = _one_error_line(capsys, ["paper", "--model", "switching", "--no-plot",
                                    "--waveforms", str(tmp_path / "plain" / "w.csv")])
    assert line == (f"dronewpt paper: error: --waveforms folder {str(tmp_path / 'plain')!r} is an existing file; "
                    "valid: a folder (created if missing)")


def test_sweep_out_is_a_file(tmp_path, capsys):
    """``sweep STUDY --out FILE`` ended with ``[Errno 17] File exists: 'FILE'``; now named like mission's --out."""
    study = Path(__file__).resolve().parents[1] / "examples" / "study_small.toml"
    (tmp_path / "plain").write_text("x")
    line = _one_error_line(capsys, ["sweep", str(study), "--out", str(tmp_path / "plain"), "--workers", "0",
                                    "--no-plot", "--no-progress"])
    assert line == (f"dronewpt sweep: error: --out {str(tmp_path / 'plain')!r} is an existing file; "
                    "valid: a folder (created if missing)")
    assert (tmp_path / "plain").read_text() == "x"


# ------------------------------------------------------------------ Ctrl-C in a re-run
def test_interrupted_rerun_keeps_the_earlier_complete_set(tmp_path, capsys, monkeypatch):
    """Ctrl-C while a mission re-run into the same --out simulates: the earlier run's summary.json was
    removed at the start, so its complete set was lost (its figures and series left without it); now
    every earlier file stays as it was until this run replaces one, and no temporary is left."""
    import mission_sim.world.runner as runner
    out = tmp_path / "m"
    out.mkdir()
    earlier = {"summary.json": b'{"policy": "step"}', "timeseries.parquet": b"PAR1 earlier", "soc.png": b"png"}
    for name, data in earlier.items():
        (out / name).write_bytes(data)

    def interrupted(*a, **k):   # Ctrl-C in the simulation
        raise KeyboardInterrupt
    monkeypatch.setattr(runner, "run_mission", interrupted)
    assert main(["mission", "--out", str(out), "--no-plot", "--no-progress"]) == 130
    assert capsys.readouterr().err == "dronewpt mission: interrupted (SIGINT)\n"
    assert {p.name: p.read_bytes() for p in out.iterdir()} == earlier


# ------------------------------------------------------------------ policy names with a parameter
def test_policy_parameter_typos_are_named(tmp_path, capsys):
    """``--policy rl:$MODEL`` with MODEL unset (``rl:``) ran the shipped model and ``step:`` the step
    policy, silently; ``model_based_budget:abc`` said only "could not convert string to float: 'abc'";
    ``rl:FOLDER`` said the folder "does not exist"."""
    def err(policy):
        return _one_error_line(capsys, ["mission", "--dry-run", "--out", str(tmp_path / "m"), "--policy", policy])
    assert err("rl:") == ("dronewpt mission: error: policy='rl:' is invalid: nothing after ':'; valid: rl alone, "
                          "or rl:PATH")
    assert err("model_based_budget:") == ("dronewpt mission: error: policy='model_based_budget:' is invalid: nothing "
                                          "after ':'; valid: model_based_budget alone, or model_based_budget:B (a number)")
    assert err("step:").startswith("dronewpt mission: error: policy='step:' is invalid; valid values: hysteresis, ")
    assert err("model_based_budget:abc") == (
        "dronewpt mission: error: policy='model_based_budget:abc' is invalid; valid: model_based_budget:B with B a "
        "number, the overshoot budget (e.g. 0.02)")
    assert err(f"rl:{tmp_path}") == (f"dronewpt mission: error: RL model file {str(tmp_path)!r} is a folder; valid: "
                                     "a model file (as `dronewpt train` writes)")
    assert main(["mission", "--dry-run", "--out", str(tmp_path / "m"), "--policy", "model_based_budget:0.02"]) == 0


# ------------------------------------------------------------------ integer options
def test_integer_options_name_their_range(capsys, tmp_path):
    """``tolerance --draws -5`` said "valid range: integer >= 0" and then ``--draws 0`` was refused (">= 1");
    ``export-controller --lpf-order 2.5`` and ``train --n-envs abc`` (``--eval-every``, ``--eval-episodes``,
    ``--checkpoint-every``) said only "invalid int value: '...'"; an integer option given a non-integer
    named no range."""
    def err(*argv):
        return _one_error_line(capsys, list(argv))
    for bad in ("-5", "0"):
        assert err("tolerance", "--draws", bad, "--out", str(tmp_path / "t")) == (
            f"dronewpt tolerance: error: argument --draws: draws='{bad}' is invalid; valid range: integer >= 1 "
            "(see dronewpt tolerance --help)")
    assert err("export-controller", "--lpf-order", "2.5", "--out", str(tmp_path / "c")) == (
        "dronewpt export-controller: error: argument --lpf-order: lpf-order='2.5' is not an integer; valid range: "
        "integer 1..8 (see dronewpt export-controller --help)")
    assert "lpf-order='9' is invalid; valid range: integer 1..8" in err("export-controller", "--lpf-order", "9")
    assert err("train", "--algo", "ppo", "--timesteps", "10", "--n-envs", "abc") == (
        "dronewpt train: error: argument --n-envs: n-envs='abc' is not an integer; valid range: integer 1..1024 "
        "(see dronewpt train --help)")
    for flag in ("--eval-every", "--eval-episodes", "--checkpoint-every"):
        assert f"{flag[2:]}='2.5' is not an integer; valid range: integer >= 1" in err(
            "train", "--algo", "ppo", "--timesteps", "10", flag, "2.5")
    assert err("sweep", "--workers", "abc").startswith(
        "dronewpt sweep: error: argument --workers: workers='abc' is not an integer; valid range: integer 0..")


def test_unwritable_out_named_before_any_work(capsys):
    """An --out that cannot be created (here under /proc, which even root cannot write; a read-only mount
    gives "Read-only file system" the same way): ``tolerance``, ``export-controller`` and ``sweep`` said
    only ``[Errno 2] No such file or directory: '...'`` (tolerance after computing its nominal link)."""
    bad = "/proc/self/newbie"
    study = str(Path(__file__).resolve().parents[1] / "examples" / "study_small.toml")
    for cmd in (["tolerance", "--draws", "10"], ["export-controller"], ["sweep", study, "--workers", "0"]):
        assert _one_error_line(capsys, [*cmd, "--out", bad]) == (
            f"dronewpt {cmd[0]}: error: --out {bad!r} is not a writable folder: No such file or directory")


# ------------------------------------------------------------------ conflicting options
def test_replay_mass_and_set_mass_conflict(capsys):
    """``replay LOG --mass 2 --set drone.mass_kg=3`` flew a 3 kg drone without a word (--set won); with
    ``--pads`` (the re-flight) too. Refused now, before the log is read."""
    log = str(Path(__file__).resolve().parent / "data" / "flightlogs" / "dronekit-python_flight.tlog")
    pads = str(MISSIONS / "dronekit_flight_pads.csv")
    for extra in ([], ["--pads", pads]):
        assert _one_error_line(capsys, ["replay", log, "--mass", "2", "--set", "drone.mass_kg=3", *extra]) == (
            "dronewpt replay: error: --mass 2 and --set drone.mass_kg=3 both set the drone's mass; valid: one of them")


# ------------------------------------------------------------------ --dry-run checks what the run checks
def test_dry_run_refuses_what_the_run_refuses(tmp_path, capsys):
    """2026-11-27: `mission --dry-run --every -1` and `--dry-run --out FILE` said "config valid" (exit 0) while the
    run itself refused both; the dry run still creates nothing."""
    afile = tmp_path / "afile"
    afile.write_text("x")
    assert _one_error_line(capsys, ["mission", "--dry-run", "--every=-1", "--out", str(tmp_path / "m")]) == (
        "dronewpt mission: error: --every -1.0 is invalid; valid range: >= 0 s (0: every step)")
    assert _one_error_line(capsys, ["mission", "--dry-run", "--out", str(afile)]) == (
        f"dronewpt mission: error: --out {str(afile)!r} is an existing file; valid: a folder (created if missing)")
    assert main(["mission", "--dry-run", "--every", "0.5", "--out", str(tmp_path / "m")]) == 0
    assert not (tmp_path / "m").exists() and afile.read_text() == "x"


def test_no_help_text_shows_a_doubled_percent_sign(capsys):
    """argparse %-formats an option's help but not a command's description: `calibrate --help` printed "the first
    70 %% of the airborne time" (2026-11-27)."""
    import argparse

    import pytest

    from mission_sim.cli import build_parser
    commands = [name for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction) for name in a.choices]
    assert {"mission", "calibrate", "sweep"} <= set(commands)   # every command the parser has, a new one too
    for cmd in ["", *commands]:   # and the top-level help
        with pytest.raises(SystemExit):
            main([cmd, "--help"] if cmd else ["--help"])
        out = capsys.readouterr().out
        assert out.startswith(f"usage: dronewpt {cmd}".rstrip()) and "%%" not in out, (cmd, out[:200])


def test_a_key_given_twice_with_different_values_is_refused(tmp_path, capsys):
    """2026-11-27: `--set drone.mass_kg=1 --set drone.mass_kg=2` (and train's `--env`, paper's `--link`) took the
    last value without a word; `train --env n_steps` was refused as "--set 'n_steps'". The same value twice is fine."""
    out = str(tmp_path / "m")
    assert _one_error_line(capsys, ["mission", "--dry-run", "--out", out, "--set", "drone.mass_kg=1",
                                    "--set", "drone.mass_kg=2"]) == (
        "dronewpt mission: error: --set drone.mass_kg is given twice (1 and 2); valid: each key once")
    assert _one_error_line(capsys, ["train", "--algo", "ppo", "--timesteps", "10", "--out", out, "--env", "n_steps=10",
                                    "--env", "n_steps=20"]) == (
        "dronewpt train: error: --env n_steps is given twice (10 and 20); valid: each key once")
    assert _one_error_line(capsys, ["train", "--algo", "ppo", "--timesteps", "10", "--out", out, "--env", "n_steps"]) == (
        "dronewpt train: error: --env 'n_steps' is invalid; valid form: KEY=VALUE (e.g. n_steps=200)")
    assert _one_error_line(capsys, ["paper", "--no-plot", "--link", "lm_h=4e-6", "--link", "lm_h=5e-6"]) == (
        "dronewpt paper: error: --link lm_h is given twice (4e-06 and 5e-06); valid: each key once")
    assert main(["mission", "--dry-run", "--out", out, "--set", "drone.mass_kg=1", "--set", "drone.mass_kg=1.0"]) == 0
    assert not (tmp_path / "m").exists()


def test_an_unknown_option_is_named_with_its_command_and_the_nearest_option(capsys):
    """2026-11-27: `dronewpt mission --polcy step` said "dronewpt: error: unrecognized arguments: --polcy", naming
    neither the command nor the option meant."""
    assert _one_error_line(capsys, ["mission", "--polcy", "step"]) == (
        "dronewpt mission: error: unrecognized argument '--polcy' (did you mean --policy?); valid: the options and "
        "arguments of dronewpt mission --help")
    assert _one_error_line(capsys, ["sweep", "s.toml", "--wokers=1"]) == (
        "dronewpt sweep: error: unrecognized argument '--wokers=1' (did you mean --workers?); valid: the options and "
        "arguments of dronewpt sweep --help")
    assert _one_error_line(capsys, ["mission", "a.toml", "b.toml"]) == (
        "dronewpt mission: error: unrecognized argument 'b.toml'; valid: the options and arguments of dronewpt "
        "mission --help")
    # before the command's name the top-level parser got it: it was named 'dronewpt mission'
    assert _one_error_line(capsys, ["--polcy", "mission"]) == (
        "dronewpt: error: unrecognized argument '--polcy' (did you mean dronewpt mission --policy? a command's "
        "options go after its name); valid: the options and arguments of dronewpt --help")
    assert _one_error_line(capsys, ["--zzz", "mission"]) == (
        "dronewpt: error: unrecognized argument '--zzz'; valid: the options and arguments of dronewpt --help")


def test_compare_help_names_every_default_row():
    """``compare --help`` lists the rows ``compare`` runs at its defaults: ``DEFAULT_POLICIES`` and the shipped
    learned kinds aggregated over their seeds (it left out ``imitation``, whose row every default run prints; the
    list is written by hand in the help so that ``--help`` imports no policy code)."""
    import argparse
    import re

    from mission_sim.cli import build_parser
    from policies.compare import DEFAULT_POLICIES, OPT_IN_SEEDS, shipped_seed_groups
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices["compare"]
    text = " ".join(next(a for a in sub._actions if a.dest == "policies").help.split())
    assert tuple(re.search(r"default: ([\w:.,]+)", text).group(1).rstrip(",;").split(",")) == DEFAULT_POLICIES
    seeds = " ".join(next(a for a in sub._actions if a.dest == "train_seeds").help.split())
    for kinds in (re.search(r"the learned rows ([\w, ]+?) are each one row", text).group(1),
                  re.search(r"the shipped ([\w, ]+?) seeds", seeds).group(1)):
        assert set(re.split(r",\s*|\s+and\s+", kinds)) == set(shipped_seed_groups()) - set(OPT_IN_SEEDS)


def test_train_env_help_names_every_key_it_takes():
    """``train --help`` names every ``--env`` key ``policies.train.env_config`` takes (the EnvConfig fields but
    ``link`` and ``reward``, and the reward weights): it named 8 of the 15, not device_tj_c, hold_tol_a, v2_updates,
    v2_refine_levels or v2_refine_tol."""
    import argparse
    import dataclasses
    import re

    from envs import EnvConfig, RewardWeights
    from mission_sim.cli import build_parser
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices["train"]
    text = " ".join(next(a for a in sub._actions if a.dest == "env").help.split())
    keys = ({f.name for f in dataclasses.fields(EnvConfig)} - {"link", "reward"}) | \
        {f.name for f in dataclasses.fields(RewardWeights)}
    assert keys == {k for k in keys if re.search(rf"(?<![\w]){k}(?![\w])", text)}


def test_every_default_a_help_text_states_is_the_one_used():
    """A ``(default N)`` in an option's help is its parser default, or for ``train``'s options that act only with
    another (parser default None: refused when given without it) the value ``train()`` then uses (the command line's
    own, else ``policies.train.ONLY_WITH_DEFAULTS``)."""
    import argparse
    import re

    from mission_sim.cli import build_parser
    from mission_sim.cli.learning import _CLI_ONLY_WITH_DEFAULTS
    from policies.train import ONLY_WITH_DEFAULTS
    subs = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    checked, wrong = 0, []
    for name, sub in subs.items():
        for act in sub._actions:
            m = re.search(r"\(default:? ([-+]?(?:\d{1,3}(?:,\d{3})+|\d[\d_]*)(?:\.\d+)?(?:e-?\d+)?)[;:,) ]",
                          act.help or "")
            if not m:
                continue
            default = act.default
            if default is None and name == "train":
                default = _CLI_ONLY_WITH_DEFAULTS.get(act.dest, ONLY_WITH_DEFAULTS.get(act.dest))
            if isinstance(default, (int, float)) and not isinstance(default, bool):
                checked += 1
                if float(m.group(1).replace(",", "")) != float(default):
                    wrong.append(f"{name} {act.option_strings[0]}: help {m.group(1)}, used {default!r}")
    assert checked >= 30 and not wrong, (checked, wrong)
