"""``benchmarks/env_bits.py``'s command line: ``--help`` prints its usage (no traceback), a bad case index is a
one-line error (exit 2), no argument prints one line per case as before: the case's fields then its hash."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def env_bits(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import env_bits
    monkeypatch.setattr(env_bits, "fingerprint", lambda *case: f"h{len(case)}")
    return env_bits


def test_help_and_bad_index(env_bits, capsys):
    with pytest.raises(SystemExit) as e:
        env_bits.main(["--help"])
    assert e.value.code == 0 and "case index 0..11" in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:
        env_bits.main(["12"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "case 12 is invalid; valid range: 0..11" in err and "Traceback" not in err


def test_lines_are_the_cases_then_their_hash(env_bits, capsys):
    env_bits.main([])
    assert capsys.readouterr().out.splitlines() == [" ".join(map(str, c)) + " h6" for c in env_bits.CASES]
    env_bits.main(["3", "0"])
    assert capsys.readouterr().out.splitlines() == ["modal random 64 700 1 300 h6", "envelope random 64 1500 1 700 h6"]
