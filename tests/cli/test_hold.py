"""``relaxgrip hold``: JSON figures, the comparison table and figure, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.clitools import run_main
from tests.rigs import RIG_FILES, RIGS

KEYS = {"twin_version", "estimator", "target_n", "temp_c", "seed", "mae_n", "rmse_n",
        "mean_signed_error_n", "median_signed_error_n", "iqr_n", "est_error_mean_n",
        "est_rmse_n", "onset_error_n", "abs_error_iqr_n"}


@pytest.mark.parametrize("rig", RIGS)
def test_hold_json_has_the_paper_statistics(monkeypatch, capsys, tmp_path: Path, rig: str):
    plot = tmp_path / "hold.png"
    code, out, err = run_main(["hold", "--estimator", "icfn", "--duration-s", "14",
                               "--target-n", "3", "--seed", "1", "--plot", plot, "--json",
                               "--rig", RIG_FILES[rig]], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d.keys() >= KEYS
    assert d["estimator"] == "icfn"
    assert d["target_n"] == 3.0
    assert d["seed"] == 1
    assert d["window_s"] == pytest.approx([5.0, 14.0])
    q25, q75 = d["iqr_n"]
    assert q25 <= d["median_signed_error_n"] <= q75
    a25, a75 = d["abs_error_iqr_n"]  # the paper's: the quartiles of |error|, about the MAE
    assert 0.0 <= a25 <= a75 <= max(abs(q25), abs(q75))
    assert 0.0 <= d["mae_n"] <= d["rmse_n"] + 1e-12
    assert plot.stat().st_size > 10_000


def test_compare_prints_the_table_and_draws_the_figure(monkeypatch, capsys, tmp_path: Path):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_main(["hold", "--compare", "--duration-s", "10", "--jobs", "1"],
                              monkeypatch, capsys)
    assert code == 0, err
    for name in ("fixed", "icfn", "relax", "observer"):
        assert name in out
    assert "estimator" in out  # whole in an 80-column console: the figures wrap instead
    assert "3.571" in out  # the window starts at 100/280 of 10 s, rounded
    assert "3.57143" not in out
    assert "MAE reduction of relax vs fixed" in out
    assert "vs icfn" in out
    assert "IQR of" in out  # the paper's IQR, of |error|, beside relax's (wrapped)
    assert "[0.055," in out
    assert "0.076]" in out
    assert (tmp_path / "relaxgrip-hold.png").stat().st_size > 10_000


def test_compare_json_is_one_object_with_every_hold(monkeypatch, capsys, tmp_path: Path):
    code, out, err = run_main(["hold", "--compare", "--duration-s", "8", "--jobs", "1",
                               "--plot", tmp_path / "c.svg", "--json"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    assert set(d["holds"]) == {"fixed", "icfn", "relax", "observer"}
    assert set(d["mae_reduction"]) == {"vs_fixed", "vs_icfn"}
    for hold in d["holds"].values():
        assert hold.keys() >= KEYS


def test_seeds_report_each_seed_and_the_mean_over_them(monkeypatch, capsys):
    code, out, err = run_main(["hold", "--compare", "--seeds", "1,4", "--duration-s", "8",
                               "--jobs", "2"], monkeypatch, capsys)
    assert code == 0, err
    assert "seeds 1,4 (2)" in out
    assert "95 % CI" in out
    assert "MAE reduction of relax vs icfn" in out
    code, out, err = run_main(["hold", "--estimator", "relax", "--seeds", "1,4",
                               "--duration-s", "8", "--jobs", "1", "--json"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["seeds"] == [1, 4]
    assert [r["seed"] for r in d["runs"]["relax"]] == [1, 4]
    assert d["summary"]["relax"]["mae_n"]["mean"] == pytest.approx(
        np.mean([r["mae_n"] for r in d["runs"]["relax"]]))
    onsets = [r["onset_error_n"] for r in d["runs"]["relax"]]
    assert d["summary"]["relax"]["onset_error_n"]["mean"] == pytest.approx(np.mean(onsets))
    code, out, err = run_main(["hold", "--seed", "4", "--duration-s", "8", "--json"],
                              monkeypatch, capsys)
    assert json.loads(out)["mae_n"] == d["runs"]["relax"][1]["mae_n"]
    # One seed has no spread: no interval, no NaN printed.
    code, out, err = run_main(["hold", "--seeds", "4", "--duration-s", "8"], monkeypatch, capsys)
    assert code == 0, err
    assert f"{d['runs']['relax'][1]['mae_n']:.4f}" in out
    assert f"relax {d['runs']['relax'][1]['onset_error_n']:+.3f}" in " ".join(out.split())
    assert "nan" not in out


@pytest.mark.parametrize(("args", "message"), [
    (["--seeds", "3-1"], "ascending"),
    (["--seeds", "a"], "seeds must look like"),
    (["--seeds", "\uff15"], "seeds must look like 10-15 or 3,5,8, got '\uff15'"),
    (["--seeds", "1,1"], "repeat"),
    (["--seeds", "1,2", "--seed", "3"], "give one of them"),
    (["--seeds", "1,2", "--plot", "x.png"], "--seeds reports figures over seeds"),
    (["--seeds", "1,2", "--record", "x.mcap"], "--seeds reports figures over seeds"),
    (["--seeds", "1,2", "--budget"], "relaxgrip budget --seeds"),
    (["--target-n", "12"], "target force"),
    (["--target-n", "0"], "target force"),
    (["--temp-c", "90"], "safe range"),
    (["--temp-c", "-300"], "safe range"),
    (["--estimator", "magic"], "--estimator"),
    (["--duration-s", "0"], "duration"),
    (["--duration-s", "1e9"], "--duration-s must be at most 3600 s"),
    (["--duration-s", "0.001"], "--duration-s must be at least 1 s"),
    # Python's float() and int() read these as 5 N and seed 10.
    (["--target-n", "0_5"], "Invalid value for '--target-n': '0_5' is not a number"),
    (["--seed", "1_0"], "Invalid value for '--seed': '1_0' is not an integer"),
    (["--temp-profile", "ramp:40:5_5:150:30"], "not a number in it"),
    (["--duration-s", "1e-300", "--record", "x.mcap"], "--duration-s must be at least 1 s"),
    (["--disturbance", "push:2:400", "--duration-s", "20"],
     "--disturbance starts at 400 s, not before the 20 s hold ends"),
    (["--temp-profile", "step:50:280"], "--temp-profile starts at 280 s"),
    (["--target-profile", "ramp:5:3:300:10"], "--target-profile starts at 300 s"),
    # A ramp from another value than the hold's made it jump there at the onset (these ran).
    (["--duration-s", "14", "--target-profile", "ramp:4:3:5:2"],
     "--target-profile ramps from 4 N but the hold's target is 5 N (--target-n)"),
    (["--duration-s", "14", "--temp-c", "45", "--temp-profile", "ramp:40:55:5:3"],
     "--temp-profile ramps from 40 °C but the hold's temperature is 45 °C (--temp-c)"),
    (["--duration-s", "14", "--seeds", "1,2", "--jobs", "1", "--target-n", "3",
      "--target-profile", "ramp:5:3:5:2"],
     "--target-profile ramps from 5 N but the hold's target is 3 N (--target-n)"),
    (["--seed", "-1"], "--seed"),
    (["--plot", "out.gif"], "plot format"),
    (["--plot", "/no/such/dir/x.png"], "does not exist"),
    (["--budget", "--estimator", "icfn"], "--budget"),
    (["--budget", "--compare"], "--budget"),
    (["--budget", "--backend", "emulator"], "--budget"),
    (["--compare", "--jobs", "0"], "--jobs must be >= 1, got 0"),
    (["--compare", "--jobs", "257"], "--jobs must be at most 256"),
])
def test_bad_input_is_refused_before_anything_starts(monkeypatch, capsys, args, message):
    code, out, err = run_main(["hold", *args], monkeypatch, capsys)
    assert code == 2
    assert message in err
    assert err.count("\n") == 1
    assert out == ""


def test_budget_prints_the_parts_of_the_estimate_error(monkeypatch, capsys):
    code, out, err = run_main(["hold", "--duration-s", "14", "--seed", "3", "--budget", "--json"],
                              monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    parts = d["error_budget"]
    # The shipped models are calibrated (relaxgrip calibrate-hold): the calibration is a part,
    # and so is the closed chain's reading blended in from 5 s of the hold on.
    assert set(parts) == {"onset_n", "relaxation_n", "closure_n", "calibration_n", "chain_n",
                          "total_n"}
    assert parts["total_n"] == pytest.approx(d["est_error_mean_n"], abs=1e-9)
    code, out, err = run_main(["hold", "--duration-s", "14", "--seed", "3", "--budget"],
                              monkeypatch, capsys)
    assert code == 0, err
    assert "error budget" in out
    assert f"= {parts['total_n']:+.3f} N" in " ".join(out.split())
    assert f"calibration {parts['calibration_n']:+.3f} N" in " ".join(out.split())
    assert f"closed chain {parts['chain_n']:+.3f} N" in " ".join(out.split())


def test_missing_or_foreign_models_are_refused(monkeypatch, capsys, tmp_path: Path):
    code, _, err = run_main(["hold", "--models", tmp_path / "none"], monkeypatch, capsys)
    assert code == 2
    assert "error:" in err
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "manifest.json").write_text('{"format": "something else"}')
    code, _, err = run_main(["hold", "--models", tmp_path / "foreign"], monkeypatch, capsys)
    assert code == 2
    assert "error:" in err


def test_budget_survey_prints_the_parts_over_seeds(monkeypatch, capsys):
    code, out, err = run_main(["budget", "--seeds", "2,5", "--duration-s", "14", "--jobs", "1",
                               "--json"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["seeds"] == [2, 5]
    assert [r["seed"] for r in d["runs"]] == [2, 5]
    assert d["parts"]["total_n"]["mean"] == pytest.approx(
        sum(r["total_n"] for r in d["runs"]) / 2)
    assert set(d["runs"][0]["twin_scatter"]) >= {"relax_scale_0", "relax_scale_1"}
    code, out, err = run_main(["budget", "--seeds", "2,5", "--duration-s", "14", "--jobs", "1"],
                              monkeypatch, capsys)
    assert code == 0, err
    text = " ".join(out.split())
    assert f"{d['parts']['total_n']['mean']:+.3f}" in text
    assert f"taken off {d['bias_free_mae_n']:.3f} N" in text
    # What relax reads of its run: each percept's row, and (two seeds) no correction fits.
    seen = d["observability"]
    assert seen["at_s"] == 5.0  # the steady state's start: 100 s of 280 s, 5 s of 14 s
    assert seen["percepts"]
    assert set(d["runs"][0]["percepts"]) >= set(seen["percepts"])
    assert "What relax reads by 5 s of the hold (the steady state's start)" in text
    assert all(name in text for name in seen["percepts"])
    assert "would leave – N" in text
    assert f"the bias alone {d['bias_free_mae_n']:.3f} N" in text


@pytest.mark.parametrize(("args", "message"), [
    (["--seeds", "3-1"], "ascending"),
    (["--seeds", "a"], "seeds must look like"),
    (["--target-n", "0"], "target force"),
    (["--temp-c", "90"], "safe range"),
    (["--duration-s", "-5"], "duration"),
    (["--duration-s", "7200"], "at most 3600 s"),
    (["--jobs", "0"], "--jobs"),
])
def test_budget_survey_refuses_bad_input(monkeypatch, capsys, args, message):
    code, out, err = run_main(["budget", *args], monkeypatch, capsys)
    assert code == 2
    assert message in err
    assert err.count("\n") == 1
    assert out == ""


@pytest.mark.parametrize(("args", "message"), [
    (["hold", "--target-n", "abc"], "Invalid value for '--target-n'"),
    (["hold", "--bogus"], "No such option: --bogus"),
    (["bogus"], "No such command 'bogus'"),
    (["recover"], "Missing argument 'recording'"),
])
def test_flags_typer_cannot_parse_are_one_line_too(monkeypatch, capsys, args, message):
    from tests.clitools import assert_one_error_line

    code, out, err = run_main(args, monkeypatch, capsys)
    assert_one_error_line(code, out, err, message)
    assert "--help)" in err


def test_bare_command_shows_its_help(monkeypatch, capsys):
    code, out, _ = run_main([], monkeypatch, capsys)
    assert code == 2
    assert out.count("Usage: ") == 1


@pytest.mark.parametrize(("command", "shown"), [
    (["hold"], "Twin seed (default: 0)."),
    (["calibrate-band"], "(default: 3000-3035)"),
    (["calibrate-hold"], "(default: 1000-1005)"),
])
def test_help_shows_the_defaults_it_states(monkeypatch, capsys, command, shown):
    # rich read "[default: ...]" in a help text as markup and dropped it.
    code, out, _ = run_main([*command, "--help"], monkeypatch, capsys)
    assert code == 0
    assert shown in " ".join(out.replace("│", " ").split())


def test_budget_survey_of_one_short_hold_reads_and_says_it(monkeypatch, capsys):
    """A 1 s hold on one seed: the percepts were NaN (windows under a frame), the title's
    steady state read 0–1 s for 0.3571–1 s, and the bias-free MAE of one seed printed nan."""
    code, out, err = run_main(["budget", "--seeds", "3", "--duration-s", "1", "--jobs", "1",
                               "--json"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["observability"]["percepts"] == ["f_onset_n", "icfn_drift_n", "motor_travel_mm",
                                              "k_n", "tau_s"]
    code, out, err = run_main(["budget", "--seeds", "3", "--duration-s", "1", "--jobs", "1"],
                              monkeypatch, capsys)
    assert code == 0, err
    text = " ".join(out.split())
    assert "estimate − true force over 0.3571–1 s" in text
    assert "taken off – N" in text
    assert "nan" not in text


def test_a_push_off_the_twin_is_refused_before_the_recording_opens(monkeypatch, capsys,
                                                                    tmp_path: Path):
    """The emulator cannot push the object: refused, but after --record had opened the file,
    and an earlier recording there was overwritten by a 10 kB stub."""
    record = tmp_path / "earlier.mcap"
    record.write_text("an earlier recording")
    code, out, err = run_main(["hold", "--backend", "emulator", "--disturbance", "push:1:1",
                               "--duration-s", "2", "--record", record], monkeypatch, capsys)
    assert code == 2
    assert "a disturbance (a push on the object) needs the twin backend" in err
    assert err.count("\n") == 1
    assert out == ""
    assert record.read_text() == "an earlier recording"


def test_record_refuses_an_existing_file_without_overwrite(monkeypatch, capsys, tmp_path: Path):
    """An earlier run's recording is not replaced by a typo: nothing runs, the file is kept."""
    old = tmp_path / "yesterday.mcap"
    old.write_bytes(b"a recording of yesterday's hold")
    code, _, err = run_main(["hold", "--duration-s", "1", "--record", old], monkeypatch,
                            capsys)
    assert code == 2
    assert err == f"error: --record {old} exists: add --overwrite to replace it\n"
    assert old.read_bytes() == b"a recording of yesterday's hold"
    code, _, err = run_main(["hold", "--record", tmp_path, "--overwrite"], monkeypatch, capsys)
    assert code == 2
    assert f"--record {tmp_path} is a directory" in err
    code, _, err = run_main(["hold", "--overwrite"], monkeypatch, capsys)
    assert code == 2
    assert "--overwrite lets --record replace a file" in err


def test_a_stopped_hold_prints_what_it_held_and_exits_130(monkeypatch, capsys, tmp_path: Path):
    """A stop signal mid-hold (here: raised by the recorder, as the handler would) prints the
    partial result, ``"interrupted": true``, closes the recording complete and exits 130."""
    from relaxgrip.recording import McapRecorder, read_session

    step = McapRecorder.step

    def stopping(self, obs, controller, command):
        step(self, obs, controller, command)
        if controller.estimate.hold_s >= 2.0:
            raise KeyboardInterrupt

    monkeypatch.setattr(McapRecorder, "step", stopping)
    path = tmp_path / "stopped.mcap"
    code, out, err = run_main(["hold", "--duration-s", "4", "--json", "--record", path],
                              monkeypatch, capsys)
    assert code == 130, err
    partial = json.loads(out)
    assert partial["interrupted"] is True
    assert 2.0 <= partial["held_s"] < 2.1
    assert partial["window_s"][0] < 2.0  # the figures of the steady state's first part
    assert partial["mae_n"] < 0.2
    assert read_session(path)["backend"]["name"] == "twin"  # complete: read strictly
    code, out, err = run_main(["hold", "--duration-s", "4", "--record", path, "--overwrite"],
                              monkeypatch, capsys)
    assert code == 130
    assert "MAE (N)" in out
    assert "interrupted after 2.0 s of the 4 s hold: motor stopped, heaters off; recording" \
        in err
