"""``pioneer.nn.checkpoint``: the one safetensors writer and reader of the students and
CrowdNav++ — round trip, metadata, and one ``DataError`` for every kind of bad file."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("safetensors")

from torch import nn  # noqa: E402

from pioneer.config import Config  # noqa: E402
from pioneer.errors import DataError  # noqa: E402
from pioneer.nn.checkpoint import (  # noqa: E402
    load_checked,
    read_checkpoint,
    stored_config,
    write_checkpoint,
)

FMT = "pioneer.test-net/1"


@dataclasses.dataclass(frozen=True)
class NetConfig(Config):
    n_in: int = 3
    n_out: int = 2


def _net(cfg: NetConfig, seed: int = 0) -> nn.Module:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Linear(cfg.n_in, 4), nn.ReLU(), nn.Linear(4, cfg.n_out))


def _read(p: Path, tensors: bool = True) -> tuple[dict, dict]:
    return read_checkpoint(p, FMT, "test net", "write it again", "train one first", tensors)


def test_round_trip_keeps_weights_config_and_info(tmp_path):
    cfg = NetConfig(n_in=5)
    model = _net(cfg)
    p = write_checkpoint(model, cfg.to_dict(), tmp_path / "net.safetensors", FMT, {"epochs": 3})
    assert p == tmp_path / "net.safetensors" and p.is_file()
    assert [q.name for q in tmp_path.iterdir()] == ["net.safetensors"]  # no temporary left

    meta, arrays = _read(p)
    assert meta == {"format": FMT, "config": cfg.to_dict(), "info": {"epochs": 3}}
    again = stored_config(p, meta, NetConfig, "fix")
    assert again == cfg
    loaded = load_checked(_net(again, seed=1), arrays, p, "NetConfig", "fix")
    assert not loaded.training
    for k, v in model.state_dict().items():
        assert torch.equal(loaded.state_dict()[k], v)


def test_metadata_only_read_skips_the_tensors(tmp_path):
    p = write_checkpoint(_net(NetConfig()), NetConfig().to_dict(), tmp_path / "n.safetensors", FMT)
    meta, arrays = _read(p, tensors=False)
    assert arrays == {} and meta["info"] == {}


def test_missing_file_names_the_missing_fix(tmp_path):
    with pytest.raises(DataError, match="train one first"):
        _read(tmp_path / "absent.safetensors")


def test_foreign_file_and_wrong_format_are_refused(tmp_path):
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"not a safetensors file")
    with pytest.raises(DataError, match=r"readable \.safetensors"):
        _read(junk)
    other = write_checkpoint(
        _net(NetConfig()), NetConfig().to_dict(), tmp_path / "o.safetensors", "other/1"
    )
    with pytest.raises(DataError, match="format"):
        _read(other)


def test_an_invalid_stored_config_names_the_file(tmp_path):
    p = write_checkpoint(_net(NetConfig()), {"n_in": 3, "bogus": 1}, tmp_path / "c.st", FMT)
    meta, _ = _read(p)
    with pytest.raises(DataError, match=r"c\.st: config"):
        stored_config(p, meta, NetConfig, "fix")


def test_tensors_that_do_not_match_the_model_are_listed(tmp_path):
    p = write_checkpoint(_net(NetConfig()), NetConfig().to_dict(), tmp_path / "n.st", FMT)
    _, arrays = _read(p)
    with pytest.raises(DataError, match="shape"):
        load_checked(_net(NetConfig(n_in=7)), arrays, p, "NetConfig", "fix")
    arrays["0.weight"] = torch.full_like(arrays["0.weight"], float("nan"))
    with pytest.raises(DataError, match="finite float32"):
        load_checked(_net(NetConfig()), arrays, p, "NetConfig", "fix")
