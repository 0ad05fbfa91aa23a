"""``dronewpt paper``: fundamental and instantaneous maxima labelled apart, ``--waveforms`` export."""

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from mission_sim.cli import main
from wpt_receiver import TABLE_I


@pytest.fixture(scope="module")
def switching_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper") / "wave.parquet"
    return out, main(["paper", "--model", "switching", "--no-plot", "--format", "json", "--waveforms", str(out)])


def test_waveforms_are_the_circuit(switching_run, capsys):
    """The exported waveforms obey the tanks' C dv/dt = i (within 2 %, finite differences), the battery
    current never reverses, the inverter and SBAR switch states are there, one block per trajectory."""
    out, status = switching_run
    assert status == 0
    df = pd.read_parquet(out)
    assert {"t_s", "i1_a", "vc1_v", "i2_a", "vc2_v", "v1_v", "v2_v", "i_load_a", "sbar_gate", "inverter_cmd",
            "trajectory"} <= set(df.columns)
    assert list(dict.fromkeys(df["trajectory"])) == ["step", "ramp", "proposed"]
    w = TABLE_I.omega_rad_s
    for name, c_f, i_col, v_col in (("c1", 1 / (w * w * TABLE_I.l1_h), "i1_a", "vc1_v"),
                                    ("c2", 1 / (w * w * TABLE_I.l2_h), "i2_a", "vc2_v")):
        d = df[df["trajectory"] == "ramp"]
        t = d["t_s"].to_numpy()
        sel = (t > 2e-3) & (t < 3e-3)
        dv = np.gradient(d[v_col].to_numpy(), t)[sel] * c_f
        i = d[i_col].to_numpy()[sel]
        assert np.max(np.abs(dv - i)) < 0.02 * np.max(np.abs(i)), name
    assert df["i_load_a"].min() > -1e-6
    assert set(df["inverter_cmd"].unique()) <= {-1, 0, 1} and set(df["sbar_gate"].unique()) == {0, 1}
    # in short mode (gate on) no current reaches the battery
    on = df["sbar_gate"] == 1
    assert np.max(np.abs(df.loc[on, "i_load_a"])) < 1e-6 * df["i_load_a"].max() + 1e-9


def test_envelope_table_labels_its_max_as_the_fundamental(switching_run, capsys):
    out, _ = switching_run
    capsys.readouterr()
    assert main(["paper", "--model", "envelope", "--no-plot"]) == 0
    text = capsys.readouterr().out
    assert "max fund." in text and "max inst." not in text
    assert main(["paper", "--model", "envelope", "--no-plot", "--format", "json"]) == 0
    rows = {r["trajectory"]: r for r in json.loads(capsys.readouterr().out)["rows"]}
    assert rows["ramp"]["max_fundamental_a"] == rows["ramp"]["max_current_a"]


def test_waveforms_bad_input_exits_2_before_simulating(tmp_path, capsys):
    assert main(["paper", "--waveforms", str(tmp_path / "w.csv"), "--no-plot"]) == 2   # the default (modal) model
    assert main(["paper", "--model", "switching", "--waveforms", str(tmp_path / "w.txt"), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "--waveforms" in err and ".parquet" in err and not list(tmp_path.iterdir())


def test_waveforms_csv_writer(tmp_path):
    from mission_sim.cli.paper import _write_waveforms
    wf = pd.DataFrame({"t_s": [0.0, 1e-6], "i2_a": [1.0, 2.0]})
    runs = [SimpleNamespace(trajectory=n, extra={"waveforms": wf}) for n in ("step", "ramp")]
    path = tmp_path / "sub" / "w.csv"
    _write_waveforms(runs, path)
    back = pd.read_csv(path)
    assert list(back.columns) == ["t_s", "i2_a", "trajectory"] and len(back) == 4
    assert back["i2_a"].tolist() == [1.0, 2.0, 1.0, 2.0]
