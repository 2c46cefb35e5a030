"""The ``pioneer demos``/``reward`` subcommands: files written, JSON printed, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pioneer.cli import main
from pioneer.reward.dataset import Dataset
from pioneer.reward.density import DensityReward


@pytest.fixture(scope="module")
def demos_file(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("demos") / "static.npz"
    argv = ["demos", "generate", "--scenario", "static", "--out", str(p)]
    assert main([*argv, "--positive", "30", "--negative", "20"]) == 0
    return p


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out)


def _one_line_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err.strip("\n")
    assert err.startswith("pioneer: error:")
    assert len(err.splitlines()) == 1
    for word in ("expected", "received", "fix", *needles):
        assert word in err, (word, err)
    return err


def test_demos_generate_writes_a_loadable_file(demos_file, tmp_path, capsys):
    d = Dataset.load(demos_file)
    assert (d.n_positive, d.n_negative) == (30, 20)
    assert d.scenarios == ("static",)
    out = tmp_path / "again.npz"
    argv = ["demos", "generate", "--scenario", "static", "--out", str(out)]
    assert main([*argv, "--positive", "30", "--negative", "20"]) == 0
    printed = _json(capsys)
    assert printed["out"] == str(out)
    assert (printed["samples"], printed["positive"], printed["negative"]) == (50, 30, 20)
    np.testing.assert_array_equal(Dataset.load(out).pose, d.pose)  # same default seed


def test_demos_show_prints_the_summary(demos_file, capsys):
    assert main(["demos", "show", str(demos_file)]) == 0
    shown = _json(capsys)
    assert (shown["samples"], shown["positive"], shown["negative"]) == (50, 30, 20)
    assert shown["scenarios"] == {"static": 50}
    assert shown["meta"]["source"] == "scripted"
    assert "feature_names" not in shown["meta"]


def test_reward_fit_then_show(demos_file, tmp_path, capsys):
    model = tmp_path / "reward.npz"
    assert main(["reward", "fit", "--demos", str(demos_file), "--out", str(model)]) == 0
    fitted = _json(capsys)
    assert fitted["out"] == str(model)
    assert fitted["n_train"] == 50 and fitted["features"] == "xy"
    assert fitted["scale"] > 0 and fitted["length_scale"] > 0
    m = DensityReward.load(model)
    assert m.feature_names == ["x", "y"]
    assert m.info_["demos"] == str(demos_file)

    assert main(["reward", "show", "--model", str(model)]) == 0
    shown = _json(capsys)
    assert shown["feature_dim"] == 2 and shown["n_train"] == 50
    assert shown["n_inducing"] == 50
    assert shown["hyperparameters"]["lam"] == 1e-2
    assert shown["demos"] == str(demos_file)
    assert 0.9 <= shown["auroc_pos_vs_neg"] <= 1.0
    assert shown["reward_positive_mean"] > shown["reward_negative_mean"]


def test_reward_fit_options(demos_file, tmp_path, capsys):
    model = tmp_path / "fps.npz"
    argv = ["reward", "fit", "--demos", str(demos_file), "--out", str(model)]
    opts = ["--max-inducing", "12", "--inducing", "fps", "--length-scale", "0.5", "--lam", "0.1"]
    assert main([*argv, *opts, "--features", "obs_action"]) == 0
    fitted = _json(capsys)
    assert fitted["n_inducing"] <= 12 and fitted["length_scale"] == 0.5
    assert fitted["features"] == "obs_action"
    m = DensityReward.load(model)
    assert len(m.feature_names) == 31 and m.config.inducing == "fps" and m.config.lam == 0.1
    # positives only, scored on the full dataset
    pos = tmp_path / "pos.npz"
    argv = ["reward", "fit", "--demos", str(demos_file), "--out", str(pos), "--min-gamma", "0"]
    assert main(argv) == 2  # one-sided by the flag: refused unless allowed, blaming the flag
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--min-gamma" in err[0] and "30 positive, 0 negative" in err[0]
    assert "--allow-one-sided" in err[0] and not pos.exists()
    assert main([*argv, "--allow-one-sided"]) == 0
    assert "warning" in capsys.readouterr().err
    only = tmp_path / "only-positive.npz"  # scored on a dataset without negatives: null
    Dataset.load(demos_file).filter(min_gamma=0).save(only)
    assert main(["reward", "show", "--model", str(pos), "--demos", str(only)]) == 0
    own = capsys.readouterr().out
    assert "NaN" not in own, own
    assert json.loads(own)["auroc_pos_vs_neg"] is None
    assert json.loads(own)["reward_negative_mean"] is None
    assert main([*argv, "--allow-one-sided"]) == 2  # the model made above is not replaced
    assert "--overwrite" in capsys.readouterr().err
    assert main([*argv, "--allow-one-sided", "--overwrite"]) == 0
    assert _json(capsys)["n_train"] == 30
    assert main(["reward", "show", "--model", str(pos), "--demos", str(demos_file)]) == 0
    shown = _json(capsys)
    assert shown["n_train"] == 30 and shown["auroc_pos_vs_neg"] is not None


def test_reward_show_missing_model_is_one_line(tmp_path, capsys):
    missing = tmp_path / "missing.npz"
    assert main(["reward", "show", "--model", str(missing)]) == 2
    _one_line_error(capsys, "missing.npz")


def test_reward_fit_bad_inputs_are_one_line(demos_file, tmp_path, capsys):
    out = tmp_path / "never.npz"
    assert main(["reward", "fit", "--demos", str(tmp_path / "nope.npz"), "--out", str(out)]) == 2
    _one_line_error(capsys, "nope.npz")
    truncated = tmp_path / "half.npz"
    raw = demos_file.read_bytes()
    truncated.write_bytes(raw[: len(raw) // 2])
    assert main(["reward", "fit", "--demos", str(truncated), "--out", str(out)]) == 2
    _one_line_error(capsys, "truncated")
    argv = ["reward", "fit", "--demos", str(demos_file), "--out", str(out), "--lam", "-1"]
    with pytest.raises(SystemExit) as refused:  # a value out of range: the command line's fault
        main(argv)
    assert refused.value.code == 2
    _one_line_error(capsys, "--lam", "> 0")
    # three episodes: no held-out split has both signs
    assert (
        main(["reward", "fit", "--demos", str(demos_file), "--out", str(out), "--select-length"])
        == 2
    )
    _one_line_error(capsys, "negative")
    assert not out.exists()


def test_demos_show_of_a_model_file_is_one_line(demos_file, tmp_path, capsys):
    model = tmp_path / "m.npz"
    assert main(["reward", "fit", "--demos", str(demos_file), "--out", str(model)]) == 0
    capsys.readouterr()
    assert main(["demos", "show", str(model)]) == 2
    _one_line_error(capsys)
