"""Issue 25, cases 1-15 and the borderline ones: the table "Issue 25" of docs/robustness.md, row by
row, in-process, each in a fresh copy of its folder. A refused row (exit 2) must print exactly one line
naming the option or key and create nothing at all (no file, no folder: checked before any work).
Plus what a table row cannot show: the plausible ranges themselves, the hyperparameter checks, the
"95 %" of ``compare --help`` and the inputs named when a run meets a NaN."""

from __future__ import annotations

import os
import re
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
from _nan_policy import NanPolicy

from mission_sim import config as mconfig
from mission_sim.cli import main

DOC = Path(__file__).resolve().parents[1] / "docs" / "robustness.md"
_ROW = re.compile(r"^\|\s*(?P<case>[^|`]+?)\s*\|\s*`(?P<cmd>[^`]+)`\s*\|\s*(?P<rc>\d+)\s*\|\s*"
                  r"`(?P<text>[^`]+)`\s*\|\s*$")


def _rows():
    section = DOC.read_text("utf-8").split("## Issue 25", 1)[1].split("\n## ", 1)[0]
    return [(m["case"], m["cmd"], int(m["rc"]), m["text"]) for line in section.splitlines() if (m := _ROW.match(line))]


ROWS = _rows()
TOY_STUDY = '[study]\nname = "{name}"\nrunner = "sweep_toy:factory"\n[grid]\n"mission.hover_time_s" = {hover}\n{more}'


def _run(argv) -> int:
    try:
        return int(main(argv))
    except SystemExit as exc:
        return int(exc.code or 0)


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """The files the table's rows run against (a FIFO is added per row: it cannot be copied)."""
    d = tmp_path_factory.mktemp("issue25")
    (d / "a_folder").mkdir()
    (d / "a_file").write_text("")
    (d / "cruise.toml").write_text("[mission]\ncruise_speed_m_s = 1e308\n")
    (d / "cut.toml").write_text("seed = 3\n[battery]\n")
    (d / "malformed.yml").write_text("learning_rate: [1,\n  gamma: 0.9\n")
    (d / "abc.json").write_text('{"learning_rate": "abc"}')
    (d / "study.toml").write_text(TOY_STUDY.format(name="study", hover="[1.0, 2.0]", more='"pads.1.x_m" = [10.0, 20.0]\n'))
    (d / "other.toml").write_text(TOY_STUDY.format(name="other", hover="[3.0, 4.0, 5.0]", more=""))
    cwd = os.getcwd()
    os.chdir(d)
    try:
        assert _run(["sweep", "study.toml", "--out", "a_sweep", "--workers", "0", "--no-plot", "--no-progress"]) == 0
    finally:
        os.chdir(cwd)
    return d


@pytest.fixture
def folder(template, tmp_path, monkeypatch):
    d = tmp_path / "run"
    shutil.copytree(template, d)
    os.mkfifo(d / "fifo")
    monkeypatch.chdir(d)
    return d


def test_the_table_has_every_case():
    cases = {c for c, *_ in ROWS}
    assert {str(i) for i in range(1, 16)} <= cases and "borderline" in cases
    assert len(ROWS) >= 25


@pytest.mark.parametrize("case,cmd,rc,expect", ROWS, ids=[f"case {r[0]}: {r[1]}" for r in ROWS])
def test_issue25_row(case, cmd, rc, expect, folder, capsys):
    before = set(folder.rglob("*"))
    got = _run(shlex.split(cmd) + (["--no-progress"] if cmd.split()[0] in ("sweep", "mission") and "--status"
                                   not in cmd else []))
    out, err = capsys.readouterr()
    assert got == rc, (out, err)
    assert "Traceback" not in out + err
    if rc == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        assert lines[0].startswith("dronewpt") and expect in lines[0], lines[0]
        assert set(folder.rglob("*")) == before  # nothing created: refused before any work
    else:
        assert expect in out + err


# ----------------------------------------------------------------------------- what a row cannot show
def test_every_numeric_key_has_a_plausible_range_holding_its_default():
    """The schema: every numeric field of every section has a range, and the default mission lies in it (strings and
    booleans, ``sim.rectify_after_pad_off``, have none)."""
    from dataclasses import fields
    cfg = mconfig.load_config()
    for sec, cls in {**mconfig._SECTIONS, "pads": mconfig.PadConfig}.items():
        for f in fields(cls):
            rng = mconfig.plausible_range(sec, f.name)
            if f.type in ("str", "bool"):
                assert rng is None
                continue
            assert rng is not None, f"{sec}.{f.name} has no plausible range"
            values = [getattr(p, f.name) for p in cfg.pads] if sec == "pads" else [getattr(getattr(cfg, sec), f.name)]
            assert all(v is None or rng.contains(v) for v in values), (sec, f.name, values, rng.text())


@pytest.mark.parametrize("key,value,text", [
    ("mission.cruise_speed_m_s", 100.0, None), ("mission.cruise_speed_m_s", 100.5, "(0, 100] m/s"),
    ("drone.mass_kg", 0.01, None), ("drone.mass_kg", 0.009, "[0.01, 1000] kg"),
    ("link.f_hz", 3e7, None), ("link.f_hz", 3.1e7, "[10000, 3e+07] Hz"),
    ("coupling.tx_min_k", 1.0, "(0, 1)"), ("battery.n_series", 33, "integer 1..32"),
    ("pads.1.hover_time_s", 1e6 + 1, "[0, 1e+06] s"), ("wind.direction_deg", -361.0, "[-360, 360] deg"),
])
def test_range_ends(key, value, text):
    """The ends of a range are accepted, a step beyond is refused naming the key and the one range text."""
    d = mconfig.apply_overrides(mconfig.load_config_dict(), {key: value})
    if text is None:
        mconfig.config_from_dict(d)
        return
    with pytest.raises(ValueError) as exc:
        mconfig.config_from_dict(d)
    assert str(exc.value) == f"{key}={value!r} is invalid; valid range: {text}"


def test_a_nan_in_a_run_names_the_inputs_that_differ_from_the_default():
    from mission_sim.world.loop import NonFiniteError
    from mission_sim.world.runner import run_mission

    cfg = mconfig.config_from_dict(mconfig.apply_overrides(mconfig.load_config_dict(), {
        "link.vdc_v": 900.0, "drone.mass_kg": 2.0, "wind.speed_m_s": 3.0}))  # wind: the default's value
    with pytest.raises(NonFiniteError) as exc:
        run_mission(cfg, NanPolicy())
    msg = str(exc.value)
    assert msg.startswith("policy 'broken' returned d_short=nan")
    # farthest first: 900 V is 1.48 decades from 30 V, 2 kg 0.30 decades from 1 kg; wind unchanged
    assert msg.endswith("farthest first: link.vdc_v=900.0, drone.mass_kg=2.0)")
    assert mconfig.differing_keys(mconfig.load_config()) == []


def test_hyperparameters_are_checked_by_name_type_and_range():
    sb3 = pytest.importorskip("stable_baselines3")
    from policies.hyperparams import check_hyperparams

    check_hyperparams({"learning_rate": 1e-3, "n_steps": 256.0, "ent_coef": 0.0, "policy_kwargs": {}}, sb3.PPO)
    check_hyperparams({"ent_coef": "auto_0.1", "train_freq": [1, "episode"]}, sb3.SAC)
    for hp, text in [({"learning_rate": "abc"}, "learning_rate='abc' is invalid; valid type: number"),
                     ({"learning_rate": 0.0}, "learning_rate=0.0 is invalid; valid range: (0, 1]"),
                     ({"gamma": float("nan")}, "gamma=nan is invalid"),
                     ({"n_steps": 1.5}, "n_steps=1.5 is invalid; valid range: integer 1..1000000000"),
                     ({"use_sde": 1}, "use_sde=1 is invalid; valid type: true or false"),
                     ({"policy_kwargs": "x"}, "policy_kwargs='x' is invalid; valid type: mapping"),
                     ({"buffer_size": 10}, "buffer_size is not a valid key for PPO")]:
        with pytest.raises(ValueError) as exc:
            check_hyperparams(hp, sb3.PPO)
        assert str(exc.value).startswith(text), (hp, str(exc.value))


def test_the_shipped_hyperparameter_files_pass_the_check():
    sb3 = pytest.importorskip("stable_baselines3")
    from policies.hyperparams import load_hyperparams
    files = sorted((Path(__file__).resolve().parents[1] / "policies" / "hyperparams").glob("*.yml"))
    assert files
    for f in files:
        load_hyperparams(f, sb3.PPO)


def test_compare_help_prints_a_single_percent_sign(capsys):
    assert _run(["compare", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "%%" not in out and "95 % bootstrap interval" in out


def test_workers_bound_follows_the_cpus(monkeypatch, capsys):
    from mission_sim.cli.common import max_workers
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2}, raising=False)
    assert max_workers() == 12
    assert _run(["sweep", "x.toml", "--out", "s", "--workers", "13"]) == 2
    # the bound is taken when the parser is built, here after the patch
    assert "valid range: integer 0..12 (4 per CPU)" in capsys.readouterr().err
