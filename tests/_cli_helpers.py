"""Helpers of the CLI newcomer tests: one refused command line, and ``telemetry --follow`` without a network."""

from __future__ import annotations


def one_error_line(capsys, argv) -> str:
    """``main(argv)``: exit status 2, nothing on stdout, one line on stderr and no traceback (the line returned)."""
    from mission_sim.cli import main
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    cap = capsys.readouterr()
    assert rc == 2, (rc, cap.err)
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in cap.err, cap.err
    assert cap.out == "", cap.out
    return lines[0]


def fake_follow(monkeypatch) -> dict:
    """``mission_sim.mavlink.follow``'s ``follow`` and ``open_follow`` replaced (no socket, no vehicle): the dict
    returned fills with the keyword arguments ``follow`` was called with."""
    from mission_sim.mavlink import follow
    seen = {}

    def fake(*a, **kw):
        seen.update(kw)
        # one position followed (none is exit 2 since 2026-11-28: tests/test_newcomer2.py)
        return follow.FollowStats(positions=1, chunks=1, frames=0, wall_s=0.0, final_soc=None, home=kw["home"])
    monkeypatch.setattr(follow, "follow", fake)
    monkeypatch.setattr(follow, "open_follow", lambda connect: type("C", (), {"close": lambda self: None})())
    return seen
