"""Robustness for a newcomer (issue #16): the bad-input table of docs/robustness.md, run row by row
in-process, plus atomic outputs, the run-size estimate against real runs, and NaN actions in the envs."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mission_sim.cli import main

DOC = Path(__file__).resolve().parents[1] / "docs" / "robustness.md"
_ROW = re.compile(r"^\|\s*`(?P<cmd>[^`]+)`\s*\|\s*(?P<rc>\d+)\s*\|\s*`(?P<text>[^`]+)`\s*\|\s*$")


def _table_rows():
    """(command, exit status, expected text) of every row of the "Bad inputs tried" table."""
    text = DOC.read_text("utf-8")
    section = text.split("## Bad inputs tried", 1)[1]
    rows = [m.groups() for line in section.splitlines() if (m := _ROW.match(line))]
    return [(cmd, int(rc), expect) for cmd, rc, expect in rows]


ROWS = _table_rows()


def _run(argv) -> int:
    try:
        return int(main(argv))
    except SystemExit as exc:  # argparse usage errors and --version
        return int(exc.code or 0)


@pytest.fixture
def bad_inputs_dir(tmp_path, monkeypatch):
    """The folder the table's commands run in (see docs/robustness.md)."""
    (tmp_path / "binary.toml").write_bytes(bytes(range(256))[::-1] + b"\x00\xd0\xff" * 15)
    (tmp_path / "bad.toml").write_text("x = = 1\n")
    (tmp_path / "a_file").write_text("")
    (tmp_path / "a_folder").mkdir()
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_table_has_the_rows():
    assert len(ROWS) >= 50
    assert all(rc in (0, 2, 3) for _, rc, _ in ROWS)


@pytest.mark.parametrize("cmd,rc,expect", ROWS, ids=[r[0] for r in ROWS])
def test_bad_input_row(cmd, rc, expect, bad_inputs_dir, capsys):
    before = set(bad_inputs_dir.rglob("*"))
    got = _run(shlex.split(cmd))
    out, err = capsys.readouterr()
    assert got == rc, (out, err)
    if rc == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        assert expect in lines[0]
        assert lines[0].startswith("dronewpt")
        assert "Traceback" not in err
        # refused before anything was written (the output folder check may create an empty folder)
        assert all(p.is_dir() for p in set(bad_inputs_dir.rglob("*")) - before)
    else:
        assert expect in out + err
