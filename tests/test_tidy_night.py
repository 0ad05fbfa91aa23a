"""Loose ends of 2026-11-27 night (tidy): `sizing --no-plot` writes no folder, `sizing --margin`'s default from the
sizing rules, the envs' one compiled-or-interpreted pick."""

from __future__ import annotations

import inspect

import pytest


def test_both_kernel_modules_pick_compiled_or_python_through_one_helper(monkeypatch):
    """``envs.vector_kernel.kernel_function`` and ``envs.modal_step.kernel_function`` each held their own one-line
    "dispatcher or its py_func" pick; one helper now (:func:`envs.vector_kernel.compiled_or_python`), the same
    functions as before (the dispatcher compiled, its ``py_func`` interpreted, a plain function itself)."""
    from envs import modal_step, vector_kernel
    from envs.vector_kernel import compiled_or_python
    for mod, names in ((vector_kernel, ("env_step", "single_step", "obs_rows", "duty_kernel")),
                       (modal_step, ("env_step", "single_step", "step_kernel"))):
        for name in names:
            f = getattr(mod, name)
            assert mod.kernel_function(name) is f
            assert mod.kernel_function(name, compiled=False) is getattr(f, "py_func", f)
            assert mod.kernel_function(name, compiled=False) is compiled_or_python(f, False)
        body = inspect.getsource(mod.kernel_function).split('"""')[-1]   # (its code, after the docstring)
        assert "py_func" not in body and "compiled_or_python(" in body   # (no copy of the pick left)
    calls = []
    monkeypatch.setattr(modal_step, "compiled_or_python", lambda f, compiled=True: calls.append(compiled) or f)
    monkeypatch.setattr(vector_kernel, "compiled_or_python", lambda f, compiled=True: calls.append(compiled) or f)
    modal_step.kernel_function("env_step", False)
    vector_kernel.kernel_function("env_step", False)
    assert calls == [False, False]
    plain = lambda: None   # noqa: E731
    assert compiled_or_python(plain, False) is plain and compiled_or_python(plain) is plain


def test_sizing_margin_default_and_help_come_from_the_sizing_rules(monkeypatch, capsys):
    """`sizing --margin`'s default and its help said 1.25, a copy of ``SizingRules.margin``: both are read from the
    rules now (a rules' margin of 1.5: the help says 1.5)."""
    import dataclasses

    import wpt_receiver.sizing as sizing
    from mission_sim.cli import main
    from mission_sim.cli.sizing import _default
    assert _default("margin") == sizing.SizingRules().margin
    with pytest.raises(SystemExit):
        main(["sizing", "--help"])
    assert f"(default {sizing.SizingRules().margin:g}, wpt_receiver.sizing.SizingRules)" in " ".join(
        capsys.readouterr().out.split())
    monkeypatch.setattr(sizing, "SizingRules", dataclasses.make_dataclass(
        "SizingRules", [("margin", float, dataclasses.field(default=1.5))], bases=(sizing.SizingRules,), frozen=True))
    assert _default("margin") == 1.5
    with pytest.raises(SystemExit):
        main(["sizing", "--help"])
    assert "(default 1.5, wpt_receiver.sizing.SizingRules)" in " ".join(capsys.readouterr().out.split())


def test_sizing_no_plot_writes_no_folder(monkeypatch, tmp_path, capsys):
    """`sizing --no-plot` writes nothing to a folder, and makes none (``out/sizing`` is made only for the figures:
    :func:`mission_sim.cli.common.prepare_out_dir` under ``not args.no_plot``); the default margin is the rules'."""
    import json

    from mission_sim.cli import main
    from wpt_receiver.sizing import SizingRules
    monkeypatch.chdir(tmp_path)
    assert main(["sizing", "--no-plot", "--no-progress", "--policies", "step", "--t-end", "0.003",
                 "--format", "json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["margin"] == SizingRules().margin and out["figures"] == []
    row = out["rows"][0]
    assert row["required_rating_a"] == pytest.approx(SizingRules().margin * row["peak_i2_a"], rel=0.01)
    assert list(tmp_path.iterdir()) == []



def test_a_long_value_is_cut_in_a_one_line_error():
    """Review of the night's merge: a 10,000-item list where a table belongs gave a 59 kB "one line"
    (``validation.check_table`` via ``shown``), and a sweep.json whose ``study`` is a 20,000-item list a 129 kB one."""
    import pytest

    from mission_sim.studies.status import _manifest_key_problem
    from mission_sim.validation import check_table, shown

    with pytest.raises(ValueError) as exc:
        check_table("[grid]", list(range(10000)), "x", eq=" = ")
    assert len(str(exc.value)) < 200 and "(10000 items)" in str(exc.value)
    assert shown([1, 2]) == "[1, 2]" and shown("a" * 100) == repr("a" * 100)   # short containers and strings whole
    text = _manifest_key_problem({"study": list(range(20000))}, "study", str, "a string")
    assert len(text) < 150 and text.startswith("'study' = [0, 1, 2") and text.endswith("valid: a string")
