"""Loose ends left by the small hours' sessions (2026-11-28, 01:35-04:35 UTC: payload drops, newcomer2), fixed on
branch loose8 (docs/changes.md, "2026-11-28, 04:35-07:35 UTC"): each test fails on the branch's start (dd62b62) and
passes here; its docstring says what it checks."""

from __future__ import annotations

import pytest

from mission_sim.cli import main


# ------------------------------------------------------------------ --follow: a bad first fix is not the reference
@pytest.mark.parametrize("bad, skipped", [({0}, 1), ({1}, 2)])
def test_follow_recovers_from_a_bad_first_fix(monkeypatch, tmp_path, capsys, bad, skipped):
    """Latitude and longitude swapped at Zurich (both in range) in the first frame became the reference: every good
    frame after it was skipped as a 5,200 km jump ('followed 1 live positions', 19 skipped). Now the reference is
    taken once CONFIRM (3) positions in a row agree: the bad fix is skipped and the rest followed. A bad second frame
    costs the good first one too (one of the two is wrong: both dropped), not the session."""
    from mission_sim.mavlink import follow
    from mission_sim.mavlink.logs import read_log
    from test_newcomer2 import _FakeVehicle, _track

    tlog = tmp_path / "z.tlog"
    monkeypatch.setattr(follow, "open_follow", lambda connect: _FakeVehicle(_track(20, bad=bad, lat0=47.4, lon0=8.5)))
    rc = main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--follow-time", "120", "--follow-idle", "0.3",
               "--connect", "none", "--tlog", str(tlog)])
    out, err = capsys.readouterr()
    assert rc == 0 and f"followed {20 - skipped} live positions" in out, (out, err)
    assert f"{skipped} implausible position(s) skipped (the first: a jump of" in err, err
    pos = read_log(tlog).position
    assert len(pos) >= 10 and pos["lat_deg"].between(47.39, 47.41).all() and pos["lon_deg"].between(8.49, 8.51).all()


def test_follow_takes_a_short_stream_that_never_reached_the_confirmation():
    """Two agreeing positions and the stream ends: both are taken (flush), nothing contradicted them."""
    import types
    from mission_sim.mavlink.follow import CONFIRM, _Positions
    pos = _Positions(None)
    msgs = [types.SimpleNamespace(time_boot_ms=100 * k, lat=473_000_000 + 20 * k, lon=85_000_000, alt=400_000)
            for k in range(CONFIRM - 1)]
    assert [pos.take(m, 0.1 * k) for k, m in enumerate(msgs)] == [[]] * (CONFIRM - 1)
    taken = pos.flush()
    assert [t for t, _, _ in taken] == [0, 100][:CONFIRM - 1] and pos.rejected == 0
    assert taken[0][2] == (0.0, 0.0, 0.0) and 0.2 < taken[1][2][1] < 0.25     # 2e-6 deg north: 0.22 m


# ------------------------------------------------------------------ mass_kg of the row holding a payload drop
def test_mission_series_mass_of_the_row_holding_the_drop_is_its_steps_mean(tmp_path, capsys):
    """PX4's delivery plan with 0.5 kg: the 1 s quiet-flight step [28, 29] s holds the drop (t = 28.5 s). Its row's
    mass_kg read 1.5 (its first sample's) while its energy was 0.6 s at 1.5 kg and 0.4 s at 1.0 kg (the summary's
    split: the samples from 28.6 s on fly light). Now the time-weighted mean of the samples' masses, as the energy is
    split: 1.3 kg, in the written parquet (the stream's path) as in run_mission's frame."""
    import json
    from pathlib import Path

    import pandas as pd

    from mission_sim.world.power import DroneParams, hover_power_w

    plan = Path(__file__).parent / "data" / "missions" / "px4_triangle_gripper_package_delivery.plan"
    rc = main(["mission", "--plan", str(plan), "--set", "drone.payload_kg=0.5", "--no-plot", "--no-progress",
               "--out", str(tmp_path)])
    capsys.readouterr()
    assert rc == 0
    d = pd.read_parquet(tmp_path / "timeseries.parquet")
    s = json.loads((tmp_path / "summary.json").read_text())
    t_r = s["first_release_t_s"]
    start = (d["t_s"] - d["dt_s"]).to_numpy()
    across = (start < t_r) & (d["t_s"].to_numpy() > t_r)
    assert across.sum() == 1
    row = d[across].iloc[0]
    m = float(row["mass_kg"])
    assert 1.0 < m < 1.5 and set(d["mass_kg"][start + 1e-9 >= row["t_s"]]) == {1.0}
    assert set(d["mass_kg"][d["t_s"] <= t_r]) == {1.5}
    # the time the row's mass says it flew light (1.5 -> 1.0 kg) holds the energy the summary puts after the drop:
    # ~ the 1.0 kg hover's power over it (a slow climb: within 5 %)
    light_s = (1.5 - m) / 0.5 * row["dt_s"]
    e_in_row = s["propulsion_energy_after_release_j"] - d["e_propulsion_j"][start >= row["t_s"] - 1e-9].sum()
    assert light_s > 0.2 and e_in_row == pytest.approx(hover_power_w(DroneParams(), 1.0) * light_s, rel=0.05)


# ------------------------------------------------------------------ a payload the drone cannot lift
def test_max_takeoff_mass_refuses_a_payload_above_it(capsys, tmp_path):
    """The power model knows no thrust limit (momentum theory gives a power for any mass; only the battery's maximum
    power stops a run): 5 kg on the default 1 kg quad flew 87.6 s until the battery gave out. ``drone.
    max_takeoff_mass_kg`` (unset by default: no limit, the default mission's dict and fingerprint unchanged) refuses
    a take-off mass above it, one line naming both, nothing written; at or below it the drone flies."""
    import dataclasses as dc

    from _cli_helpers import one_error_line

    from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config
    from mission_sim.world.power import DroneParams

    out = tmp_path / "m"
    assert one_error_line(capsys, ["mission", "--dry-run", "--out", str(out), "--set", "drone.payload_kg=5",
                                   "--set", "drone.max_takeoff_mass_kg=3"]) == (
        "dronewpt mission: error: drone.payload_kg=5.0 is invalid: the take-off mass mass_kg + payload_kg = 6 kg is "
        "above max_takeoff_mass_kg=3.0 kg; valid range: [0, 2] kg (a payload the drone can lift)")
    assert not out.exists()
    base = config_to_dict(load_config())
    assert "max_takeoff_mass_kg" not in base["drone"]      # unset: left out (TOML has no null), as before
    ok = config_from_dict(apply_overrides(base, {"drone.payload_kg": 2.0, "drone.max_takeoff_mass_kg": 3.0}))
    assert ok.drone.total_mass_kg == 3.0 and config_to_dict(ok)["drone"]["max_takeoff_mass_kg"] == 3.0
    assert config_from_dict(config_to_dict(ok)) == ok
    with pytest.raises(ValueError, match=r"^payload_kg=2\.5 is invalid: .* = 3\.5 kg is above max_takeoff_mass_kg"):
        dc.replace(ok.drone, payload_kg=2.5)   # (a MissionConfig changed in Python: the same check)
    with pytest.raises(ValueError, match=r"^mass_kg=4\.0 is invalid; valid range: \[0\.01, max_takeoff_mass_kg=3\.0\]"):
        DroneParams(mass_kg=4.0, max_takeoff_mass_kg=3.0)
    # calibrate's [drone] TOML writes the limit when set, no line when unset
    from types import SimpleNamespace

    from mission_sim.mavlink.calibrate import drone_toml
    report = {"log": "x", "battery_source": "y", "calibrated_heldout_energy_error_rel": 0.0,
              "default_heldout_energy_error_rel": 0.0, "mass_fixed": True}
    assert "max_takeoff_mass_kg" not in drone_toml(SimpleNamespace(report=report, drone=DroneParams()))
    assert "max_takeoff_mass_kg = 3\n" in drone_toml(SimpleNamespace(report=report, drone=ok.drone))


# ------------------------------------------------------------------ NAV_PAYLOAD_PLACE (94)
def _place_plan(path, p1=0.0, place_alt=0.0, place_frame=3):
    """Take off to 10 m, a waypoint 40 m north, NAV_PAYLOAD_PLACE 40 m east of it (max descent p1), RTL."""
    import json
    lat0, lon0 = 47.397742, 8.545594
    def item(cmd, lat=0.0, lon=0.0, alt=0.0, p1=0.0, frame=3):
        return {"type": "SimpleItem", "command": cmd, "frame": frame, "autoContinue": True,
                "params": [p1, 0, 0, None, lat, lon, alt]}
    items = [item(22, alt=10.0), item(16, lat0 + 40 / 111_200, lon0, 10.0),
             item(94, lat0 + 40 / 111_200, lon0 + 40 / 75_100, place_alt, p1=p1, frame=place_frame), item(20)]
    path.write_text(json.dumps({"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
                                "mission": {"version": 2, "firmwareType": 3, "vehicleType": 2, "items": items,
                                            "plannedHomePosition": [lat0, lon0, 488.0]},
                                "geoFence": {"version": 2, "polygons": [], "circles": []},
                                "rallyPoints": {"version": 2, "points": []}}))
    return path


def test_payload_place_descends_releases_at_the_ground_and_climbs_back(tmp_path, capsys):
    """NAV_PAYLOAD_PLACE was 'command NAV_PAYLOAD_PLACE (94) is not supported' (exit 2). ArduCopter flies it: to its
    position at the current height (the item's altitude unused), down until the payload touches the ground, release,
    back up. Now the route does that (the ground at home's altitude), one warning naming what is not modelled; a max
    descent (param1) that stops above the ground releases nothing (ArduCopter completes the item without releasing),
    warned. The run: one release at the bottom, the drone back at 10 m after it."""
    import json
    import warnings

    import pandas as pd

    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import route_from_items
    from wpt_receiver.notices import DronewptWarning

    plan = _place_plan(tmp_path / "place.plan", place_alt=25.0)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        route = route_from_items(read_mission(plan))
    said = [str(w.message) for w in rec if issubclass(w.category, DronewptWarning)]
    assert [(w["action"], round(w["x_m"]), round(w["y_m"]), w["z_m"], w.get("release", 0)) for w in route][1:5] == [
        ("waypoint", 0, 40, 10.0, 0), ("waypoint", 40, 40, 10.0, 0), ("waypoint", 40, 40, 0.0, 1),
        ("waypoint", 40, 40, 10.0, 0)]
    assert len(said) == 1 and "NAV_PAYLOAD_PLACE (94) flown as ArduCopter flies it" in said[0]
    assert "not modelled: the payload's hang below the drone" in said[0]
    # a max descent of 4 m from 10 m: no release there
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        route = route_from_items(read_mission(_place_plan(tmp_path / "short.plan", p1=4.0)))
    assert [w["z_m"] for w in route][3:5] == [6.0, 10.0] and not any(w.get("release") for w in route)
    assert any("max descent stops above the ground" in str(w.message) for w in rec)
    # the mission: dropped at the bottom
    rc = main(["mission", "--plan", str(plan), "--set", "drone.payload_kg=0.5", "--no-plot", "--no-progress",
               "--out", str(tmp_path / "o")])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "warning: " in err and "NAV_PAYLOAD_PLACE (94) flown as ArduCopter" in err
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["payload_releases"] == 1 and s["landing_mass_kg"] == 1.0
    d = pd.read_parquet(tmp_path / "o" / "timeseries.parquet")
    at = d["t_s"].sub(s["first_release_t_s"]).abs().idxmin()
    assert d["z_m"][at] < 0.5 and d["x_m"][at] == pytest.approx(40, abs=1) and d["z_m"][at:].max() > 9.9
    # on the ground: refused
    raw = read_mission(plan)
    import dataclasses as dc
    raw = dc.replace(raw, items=(raw.items[2],) + raw.items)
    with pytest.raises(ValueError, match=r"NAV_PAYLOAD_PLACE on the ground is not supported"):
        route_from_items(raw)


# ------------------------------------------------------------------ DRONEWPT_CACHE_DIR that cannot be used
@pytest.mark.parametrize("kind", ["file", "under_a_file"])
def test_an_unusable_cache_dir_is_said_once_per_process_tree(tmp_path, kind):
    """DRONEWPT_CACHE_DIR set to a file (or below one) turned the disk cache off silently: every run rebuilt the
    coupling tables and the ahead-of-time build (the default mission: 33 s of wall time instead of 0.8 s), no word.
    Now one warning on stderr at import naming the setting, why, and what is used instead; the processes started
    after it (spawned and forked workers importing the package again) do not repeat it. A usable folder: silent."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    afile = tmp_path / "cache_is_a_file"
    afile.write_text("")
    target = afile if kind == "file" else afile / "sub"
    script = tmp_path / "workers.py"
    script.write_text("import multiprocessing as mp\nimport wpt_receiver\n\n"
                      "def f(_):\n    import wpt_receiver\n    return 1\n\n"
                      "if __name__ == '__main__':\n"
                      "    for method in ('spawn', 'fork'):\n"
                      "        with mp.get_context(method).Pool(2) as pool:\n"
                      "            assert sum(pool.map(f, range(4))) == 4\n")
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "DRONEWPT_CACHE_DIR": str(target), "PYTHONPATH": root}
    env.pop("DRONEWPT_CACHE_DIR_WARNED", None)
    run = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    said = [ln for ln in run.stderr.splitlines() if "DRONEWPT_CACHE_DIR=" in ln]
    why = "is a file, not a folder" if kind == "file" else f"cannot be made: {str(afile)!r} is a file"
    assert said == [f"dronewpt: warning: DRONEWPT_CACHE_DIR={str(target)!r} {why}: the disk cache is off (the coupling "
                    "tables and the mission loop's ahead-of-time build are rebuilt in every run: tens of seconds "
                    "each); valid: a folder this user can write (or DRONEWPT_CACHE_DIR= empty to turn the cache off "
                    "without this warning)"], run.stderr
    ok = subprocess.run([sys.executable, "-c", "import wpt_receiver"], capture_output=True, text=True, timeout=300,
                        env={**env, "DRONEWPT_CACHE_DIR": str(tmp_path / "fine" / "cache")})
    assert ok.returncode == 0 and "DRONEWPT_CACHE_DIR" not in ok.stderr, ok.stderr


# ------------------------------------------------------------------ earlier partial recordings beside a stream's .tlog
def test_telemetry_names_earlier_partial_recordings_and_keeps_them(tmp_path, capsys):
    """Streams cut short leave X.partial.tlog, X.partial.2.tlog, ... (never overwritten, never deleted: they are
    recordings); they piled up unnoticed. A stream that finds some says so in one line naming them, and still
    leaves them byte for byte; no earlier partial: nothing said."""
    tlog = tmp_path / "x.tlog"
    kept = {tmp_path / "x.partial.tlog": b"one", tmp_path / "x.partial.3.tlog": b"three",
            tmp_path / "x.partial.abc.tlog": b"not ours", tmp_path / "y.partial.tlog": b"other target"}
    for p, data in kept.items():
        p.write_bytes(data)
    rc = main(["telemetry", "--connect", "none", "--tlog", str(tlog), "--duration", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 0 and tlog.stat().st_size > 0
    assert err == [f"dronewpt telemetry: warning: {str(tlog)!r}: 2 earlier partial recording(s) beside it, from "
                   "streams cut short, kept as they are: 'x.partial.tlog', 'x.partial.3.tlog'; this stream writes "
                   "'x.partial.2.tlog' (renamed to 'x.tlog' when it ends); valid: move or delete them once read "
                   "(dronewpt never does)"], err
    assert all(p.read_bytes() == data for p, data in kept.items())
    assert not (tmp_path / "x.partial.2.tlog").exists()
    for p in list(kept)[:2]:
        p.unlink()
    rc = main(["telemetry", "--connect", "none", "--tlog", str(tlog), "--duration", "1"])
    assert rc == 0 and capsys.readouterr().err == ""


# ------------------------------------------------------------------ train: imitation only ends with a summary line
def _imitation_meta(teacher="model_based", iterations=((1200, 0.0812), (2400, 0.04567))):
    """The metadata an imitation-only run writes (policies.imitation._save): timesteps 0, the fits' log."""
    return {"algo": "ppo", "timesteps": 0, "imitation": {
        "teacher": teacher, "dagger": len(iterations) - 1,
        "iterations": [{"iteration": k, "samples": n, "train_rms_action": rms} for k, (n, rms) in enumerate(iterations)]}}


def test_train_imitation_only_summary_line_is_made_from_the_clone_s_record():
    """``train --imitate T --timesteps 0`` ended with the file lines and no summary (final_summary had no evaluation
    and no training episodes to show). Now one line from the clone's record: teacher, fits, samples, the last fit's
    RMS action error (as in imitation.json), and the compare command that evaluates it (its argument quoted for a
    shell: a model path with a space); nothing re-evaluated. (A synthetic record: the real run took 92 s.)"""
    from policies.train import final_summary
    line = final_summary(_imitation_meta(), "/runs/my run/ppo_sbar.zip")
    assert line == ("imitation only (--timesteps 0): model_based cloned in 2 fit(s) (1 DAgger iteration(s)), 2,400 "
                    "samples, the last fit's RMS action error 0.04567 on its training data; nothing was evaluated: "
                    "`dronewpt compare --policies 'imitation:/runs/my run/ppo_sbar.zip,model_based'` measures it "
                    "against its teacher")
    assert "--policies imitation:MODEL.zip,mpc`" in final_summary(_imitation_meta("mpc", ((10, 0.5),)))
    assert final_summary({**_imitation_meta(), "timesteps": 5000}) is None   # fine-tuned: not imitation only


def test_train_imitation_only_cli_prints_the_summary_last(monkeypatch, tmp_path, capsys):
    """The CLI path: train's written metadata read back, the summary printed after the file lines, with the model's
    path (train() itself monkeypatched: the clone's fitting is not what this checks)."""
    import json

    import policies
    import policies.train as train_mod
    seen = {}

    def fake_train(algo, timesteps, out_dir, **kw):
        seen.update(kw, algo=algo, timesteps=timesteps)
        meta = tmp_path / "imit" / "ppo_sbar.json"
        meta.write_text(json.dumps(_imitation_meta()))
        return {"model": str(tmp_path / "imit" / "ppo_sbar.zip"), "meta": str(meta)}

    monkeypatch.setattr(policies, "require_sb3", lambda: None)
    monkeypatch.setattr(train_mod, "train", fake_train)
    out = tmp_path / "imit"
    rc = main(["train", "--algo", "ppo", "--timesteps", "0", "--imitate", "model_based", "--dagger", "1",
               "--imitation-episodes", "2", "--imitation-epochs", "1", "--scenario", "nominal", "--no-progress",
               "--out", str(out)])
    lines = capsys.readouterr().out.strip().splitlines()
    assert rc == 0 and seen["timesteps"] == 0 and seen["imitate"] == "model_based" and seen["dagger"] == 1
    assert lines[-1] == train_mod.final_summary(_imitation_meta(), str(out / "ppo_sbar.zip"))
    assert lines[-1].startswith("imitation only (--timesteps 0): model_based cloned in 2 fit(s)")


# ------------------------------------------------------------------ pads files: long values cut in the one-line error
@pytest.mark.parametrize("doc, said", [
    ({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {},
                                                 "geometry": {"type": "Point", "coordinates": "COORDS"}}]},
     "feature 0: coordinates [[8.5, 47.4], [8.50001, 47.4], [8.50002, 47.4], [8.50003, 47... (2000 items) are invalid; "
     "valid: [lon, lat] or [lon, lat, alt], JSON numbers"),
    ({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"hover_time_s": "COORDS"},
                                                 "geometry": {"type": "Point", "coordinates": [8.5, 47.4]}}]},
     "feature 0: hover_time_s=[[8.5, 47.4], [8.50001, 47.4], [8.50002, 47.4], [8.50003, 47... (2000 items) is "
     "invalid; valid range: [0, 1e+06] s, a JSON number"),
    ({"type": "F" * 5000, "features": []},
     "type '" + "F" * 59 + "... (5000 characters) is not GeoJSON's, not a pads file; valid: a GeoJSON "
     "FeatureCollection of Point / MultiPoint features (or one Feature or geometry), or a CSV lat,lon[,alt]"
     "[,hover_time_s]"),
    ("lat,lon,hover_time_s\n47.4,8.5," + "9" * 3000 + "\n",
     "line 2: hover_time_s='" + "9" * 59 + "... (3000 characters) is invalid; valid range: [0, 1e+06] s"),
], ids=["coordinates", "hover_time_s-array", "type-5000-chars", "csv-hover-3000-digits"])
def test_pads_file_errors_cut_a_long_value(tmp_path, capsys, doc, said):
    """A 2,000-point coordinate array given as a Point's coordinates (or as hover_time_s) was echoed whole: a 34 kB
    error line; a 3,000-digit hover time in a CSV, a 5,000-character "type", 3-5 kB. Now the value's first 60
    characters and its size; the key, the feature or line, and the valid range stay."""
    import json

    from _cli_helpers import one_error_line
    coords = [[round(8.5 + i * 1e-5, 5), 47.4] for i in range(2000)]
    if isinstance(doc, str):
        path = tmp_path / "pads.csv"
        path.write_text(doc)
    else:
        path = tmp_path / "pads.geojson"
        path.write_text(json.dumps(doc).replace('"COORDS"', json.dumps(coords)))
    line = one_error_line(capsys, ["mission", "--dry-run", "--pads", str(path), "--out", str(tmp_path / "o")])
    assert line == f"dronewpt mission: error: {path.name}: {said}" and len(line) < 400


def test_follow_with_two_positions_ends_after_the_idle_time(monkeypatch, tmp_path, capsys):
    """A vehicle that sends 2 positions (fewer than CONFIRM) and stops: they are followed once --follow-idle passes,
    not only at --follow-time (they are held for the reference, and count as come). Counted in polls of the vehicle
    (each waits 0.05 s when nothing comes): ~10 after 0.5 s idle, ~600 had it waited the 30 s."""
    from test_newcomer2 import _FakeVehicle, _track

    class Counting(_FakeVehicle):
        polls = 0

        def recv_match(self, *a, **k):
            Counting.polls += 1
            return super().recv_match(*a, **k)

    follow_two_positions(monkeypatch, tmp_path, capsys, Counting(_track(2, lat0=47.4, lon0=8.5)), 30)
    assert Counting.polls < 200, Counting.polls


def follow_two_positions(monkeypatch, tmp_path, capsys, vehicle, follow_time_s):
    """``telemetry --follow`` of ``vehicle`` (a fake whose track holds 2 positions), --follow-idle 0.5 s: both are
    followed (exit 0)."""
    from mission_sim.mavlink import follow
    monkeypatch.setattr(follow, "open_follow", lambda connect: vehicle)
    rc = main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--follow-time", str(follow_time_s), "--follow-idle",
               "0.5", "--connect", "none", "--tlog", str(tmp_path / "two.tlog")])
    out = capsys.readouterr().out
    assert rc == 0 and "followed 2 live positions" in out, out


def test_an_installed_copy_names_where_numba_s_cache_went(tmp_path):
    """An installed copy (its package folder in site-packages) with DRONEWPT_CACHE_DIR a file: numba's cache goes to
    a private temporary folder (place_numba_cache, as before); the warning names that folder too. In a fresh
    interpreter (place_numba_cache sets NUMBA_CACHE_DIR for the process)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    afile = tmp_path / "c"
    afile.write_text("")
    pkg = tmp_path / "lib" / "site-packages" / "wpt_receiver"
    pkg.mkdir(parents=True)
    code = ("import os\nfrom wpt_receiver.kernel_cache import place_numba_cache, numba_fallback\n"
            "from wpt_receiver.diskcache import WARNED_VAR, warn_unusable\n"
            "os.environ.pop(WARNED_VAR)\n"   # (the checkout's own import said it, without a numba folder to name)
            f"folder = place_numba_cache({str(pkg)!r})\n"
            "assert folder is not None and folder == numba_fallback() and os.environ['NUMBA_CACHE_DIR'] == str(folder)\n"
            "print(warn_unusable(numba_fallback()))\nprint(folder)\n")
    root = str(Path(__file__).resolve().parents[1])
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "DRONEWPT_CACHE_DIR_WARNED")}
    env.update(DRONEWPT_CACHE_DIR=str(afile), PYTHONPATH=root)
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    *_, said, folder = run.stdout.strip().splitlines()
    assert said.startswith(f"dronewpt: warning: DRONEWPT_CACHE_DIR={str(afile)!r} is a file, not a folder: the disk "
                           "cache is off") and f", numba's cache is in {folder!r};" in said
