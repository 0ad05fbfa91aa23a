"""The numbers documented in docs/devices.md, re-measured (read from the page, not copied)."""

import re
from pathlib import Path

import numpy as np
import pytest

from wpt_receiver import TABLE_I as P
from wpt_receiver.modal import ModalEnvelope
from wpt_receiver.switching import SwitchingConfig, SwitchingLink

DOC = (Path(__file__).resolve().parents[1] / "docs" / "devices.md").read_text()


def _row(label):
    line = next(ln for ln in DOC.splitlines() if ln.startswith(f"| {label} |"))
    return [c.strip() for c in line.strip("|").split("|")[1:]]


@pytest.mark.parametrize("j", [0, 1, 5])
def test_fixed_duty_table(j):
    duties = [float(c) for c in _row("d (steady)")]
    sw = [float(c) for c in _row("switching [A]")]
    est = [float(re.sub("[^0-9.+-]", "", c.replace("−", "-"))) for c in _row("exact-mode + ripple")]
    d = duties[j]
    link = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64))
    peak = link.simulate(np.full(24, d)).envelope()["i2_env_a"].to_numpy()[-8:].max()
    assert peak == pytest.approx(sw[j], abs=3e-3)   # the doc used 256 samples per half cycle
    _, e = ModalEnvelope(P).steady_peak(d)
    assert 100 * (e / peak - 1) == pytest.approx(est[j], abs=0.03)
