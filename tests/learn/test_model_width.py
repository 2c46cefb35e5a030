"""Models of the wrong width or feature layout are refused when they load — one line, before any
output — not on their first decision (an ONNX graph, a safetensors student, a reward model)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pioneer.cli import main
from pioneer.data import shipped_demos
from pioneer.deploy import StudentRuntime
from pioneer.errors import DataError
from pioneer.learn import MDN, StudentConfig, save_student
from pioneer.learn.policy import make_student_policy
from pioneer.reward.dataset import Dataset
from pioneer.reward.density import DensityReward
from pioneer.reward.recipe import PLAIN_RECIPE, check_reward_fits, fit_reward
from pioneer_testutils import assert_house_message, file_tree, one_error_line, wrong_width_onnx

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """A 28-wide ONNX that claims 29 in its metadata, a 28-wide student checkpoint and a reward
    fitted on the static study's (x, y) features."""
    d = tmp_path_factory.mktemp("models")
    onnx = wrong_width_onnx(d / "w28.onnx")
    ckpt = d / "w28.safetensors"
    save_student(MDN(StudentConfig(obs_dim=28, hidden=(8, 8), n_components=2), seed=0), ckpt)
    xy = d / "xy.reward.npz"
    fit_reward(Dataset.load(shipped_demos("static")), PLAIN_RECIPE).save(xy)
    return {"onnx": onnx, "ckpt": ckpt, "xy": xy}


def test_an_onnx_graph_of_another_width_is_refused_at_load(models):
    with pytest.raises(DataError) as err:
        StudentRuntime(models["onnx"])
    assert_house_message(str(err.value), "input 'obs'", "(N, 29)", "28")


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--scenario", "static", "--policy", "student-onnx:model=MODEL"],
        [
            "eval",
            "--scenario",
            "static",
            "--policy",
            "student-onnx:model=MODEL",
            "--seeds",
            "1",
            "--trials",
            "1",
            "--workers",
            "1",
            "--out",
            "OUT",
        ],
    ],
    ids=["run", "eval"],
)
def test_a_wrong_width_onnx_is_one_line_before_any_output(models, tmp_path, capsys, argv):
    """It loaded, then failed on the first decision with onnxruntime's 40-line traceback."""
    argv = [
        a.replace("MODEL", str(models["onnx"])).replace("OUT", str(tmp_path / "ev")) for a in argv
    ]
    code = main(argv)
    one_error_line(capsys.readouterr().err, code, "input 'obs'", "28")
    assert list(tmp_path.iterdir()) == []


def test_a_student_checkpoint_of_another_width_is_refused(models, tmp_path, capsys):
    with pytest.raises(DataError) as err:
        make_student_policy(models["ckpt"], scenario="static")
    assert_house_message(str(err.value), "obs_dim", "29", "28")
    policy = f"student-mdn:checkpoint={models['ckpt']}"
    argv = ["eval", "--scenario", "static", "--policy", policy, "--seeds", "1", "--trials", "1",
            "--workers", "1", "--out", str(tmp_path / "ev")]  # fmt: skip
    code = main(argv)
    one_error_line(capsys.readouterr().err, code, "obs_dim")
    assert list(tmp_path.iterdir()) == []


def test_a_static_study_reward_is_refused_for_the_elevator_teacher(models, tmp_path, capsys):
    """It ran and exited 0, scoring elevator rollouts by the robot's (x, y) alone."""
    model = DensityReward.load(models["xy"])
    with pytest.raises(DataError) as err:
        check_reward_fits(model, "hr-rl", str(models["xy"]))
    assert_house_message(str(err.value), "(x, y)", "hr-rl")
    assert check_reward_fits(model, "static", "xy") == "xy"
    for argv in (
        ["run", "--scenario", "hr-rl", "--policy", f"teacher:reward={models['xy']}"],
        [
            "eval",
            "--scenario",
            "hr-rl",
            "--policy",
            f"teacher:reward={models['xy']}",
            "--out",
            str(tmp_path / "ev"),
        ],
        [
            "distill",
            "--scenario",
            "hr-rl",
            "--reward",
            str(models["xy"]),
            "--out",
            str(tmp_path / "dagger"),
        ],
    ):
        before = file_tree(tmp_path)
        code = main(argv)
        one_error_line(capsys.readouterr().err, code, "(x, y)", str(models["xy"]))
        assert file_tree(tmp_path) == before


def test_a_reward_whose_features_do_not_match_its_feature_map_is_refused_at_load(tmp_path):
    """A model that names its feature map must hold exactly that map's features."""
    d = Dataset.load(shipped_demos("static"))
    model = fit_reward(d, PLAIN_RECIPE)
    model.info_["features"] = "obs_action"  # 31 features, but the model has 2
    path = tmp_path / "bad.npz"
    model.save(path)
    with pytest.raises(DataError) as err:
        DensityReward.load(path)
    assert_house_message(str(err.value), "features", "obs_action", "2 features")


def test_a_reward_of_the_right_family_but_another_width_is_refused(tmp_path):
    rng = np.random.default_rng(0)
    z = rng.normal(size=(40, 5))
    model = DensityReward().fit(z, np.where(rng.random(40) < 0.5, 1.0, -1.0))
    with pytest.raises(DataError) as err:
        check_reward_fits(model, "hr-rl", "five.npz")
    assert_house_message(str(err.value), "31 features", "5 features")  # the default map's
