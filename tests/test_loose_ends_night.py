"""Loose ends left by the evening's sessions (2026-11-27 night; docs/changes.md, "2026-11-27 night"): each test fails
on the branch's start (f378fbc) and passes here; its docstring says what it checks."""

from __future__ import annotations

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
