"""The paper's protocol in the training loop: the encoder from pretrained weights, frozen for a
warm-up or throughout, its own learning rate, and its features computed once when frozen."""

import pytest
import torch

from handmesh_tutorial import train as T
from handmesh_tutorial.apps.demo.config import RECIPES
from handmesh_tutorial.data import augment as A
from handmesh_tutorial.nn import pose_encoder as PE
from handmesh_tutorial.testing import toy_sample
from handmesh_tutorial.train import features as FT

torch.set_num_threads(1)

TINY = {"image_size": 32, "channels": (4, 4, 8, 8, 8), "latent_channels": 8, "threads": 1,
        "progress": False, "durable": False, "encoder": "resnet10", **RECIPES["cpu"]}


@pytest.fixture(scope="module")
def samples():
    return [toy_sample(i, image_size=64) for i in range(8)]


@pytest.fixture(scope="module")
def encoder_file(tmp_path_factory):
    torch.manual_seed(3)
    return PE.export_pose_encoder(PE.build_pose_net("resnet10"),
                                  tmp_path_factory.mktemp("enc") / "enc.pt", weights="float32")


def _data(samples):
    return (A.InterSHTorchDataset(samples[:6], 32, train=True, augment=False),
            A.InterSHTorchDataset(samples[6:], 32, train=False))


def _run(samples, out, **kw):
    tr, va = _data(samples)
    cfg = T.TrainConfig(out_dir=str(out),
                        **{"epochs": 2, "batch_size": 3, "lr": 1e-3, **TINY, **kw})
    return T.train(cfg, dataset=tr, val_dataset=va)


def test_config_checks():
    with pytest.raises(ValueError, match="exclude each other"):
        T.TrainConfig(init="pretrained", init_encoder="pretrained")
    with pytest.raises(ValueError, match="freeze_encoder"):
        T.TrainConfig(freeze_encoder=-1)
    with pytest.raises(ValueError, match="encoder_lr_scale"):
        T.TrainConfig(encoder_lr_scale=-0.5)


def test_frozen_encoder_keeps_the_pretrained_weights_and_the_rest_learns(samples, tmp_path,
                                                                         encoder_file):
    src, _ = PE.read_pose_encoder(encoder_file)
    res = _run(samples, tmp_path / "frozen", init_encoder=str(encoder_file), freeze_encoder=2)
    for k, v in src.encoder.state_dict().items():  # weights and BatchNorm statistics
        assert torch.equal(res.model.encoder.state_dict()[k], v), k
    fresh = T.build_model_from_config(T.TrainConfig(**{k: v for k, v in TINY.items()}),
                                      T.resolve_template(None))
    moved = [k for k, v in res.model.decoder.state_dict().items()
             if not torch.equal(v, fresh.decoder.state_dict()[k])]
    assert moved  # the decoder trained


def test_warm_up_then_fine_tune_at_a_lower_rate(samples, tmp_path, encoder_file):
    src, _ = PE.read_pose_encoder(encoder_file)
    one = _run(samples, tmp_path / "w1", init_encoder=str(encoder_file), freeze_encoder=1,
               encoder_lr_scale=0.1, epochs=1)
    for k, v in src.encoder.state_dict().items():
        assert torch.equal(one.model.encoder.state_dict()[k], v), k
    two = _run(samples, tmp_path / "w2", init_encoder=str(encoder_file), freeze_encoder=1,
               encoder_lr_scale=0.1)
    w0 = src.encoder.backbone.conv1.weight
    w2 = two.model.encoder.backbone.conv1.weight
    assert not torch.equal(w0, w2)  # the second epoch trained the encoder
    ck = torch.load(two.checkpoint, weights_only=True)
    lrs = [g["lr"] for g in ck["optimizer"]["param_groups"]]
    assert lrs == pytest.approx([1e-3, 1e-4])  # the encoder's group at a tenth


def test_stored_features_give_the_network_of_the_plain_path(samples, tmp_path, encoder_file,
                                                            monkeypatch):
    FT.clear_feature_cache()
    kw = {"init_encoder": str(encoder_file), "freeze_encoder": 2}
    cached = _run(samples, tmp_path / "cached", **kw)
    assert len(FT._MEMO) == 2  # the training and the validation crops' features were stored
    monkeypatch.setattr("handmesh_tutorial.train.loop.is_deterministic", lambda ds: False)
    plain = _run(samples, tmp_path / "plain", **kw)
    # encoding in other batch sizes changes the features in the last float bits; Adam's first
    # steps (update ~ lr * sign(gradient)) can amplify that for tiny gradients, so compare what
    # the networks predict, to a hundredth of a millimetre
    _, va = _data(samples)
    x = torch.stack([va[i]["image"] for i in range(len(va))])
    with torch.no_grad():
        a = cached.model.eval()(x)["vertices"]
        b = plain.model.eval()(x)["vertices"]
    assert float((a - b).abs().max()) < 1e-5
    assert [r["val_pa_mpjpe"] for r in cached.history] == pytest.approx(
        [r["val_pa_mpjpe"] for r in plain.history], abs=1e-2)


def test_encoded_dataset_items_and_refusals(samples):
    FT.clear_feature_cache()
    enc = PE.build_pose_net("resnet10").encoder.eval()
    _, va = _data(samples)
    ds = FT.EncodedDataset(va, enc)
    item = ds[1]
    assert "image" not in item and item["features"].shape == (512,)
    assert item["uv"].shape == (21, 2)
    assert torch.equal(item["vertices"], va[1]["vertices"])
    with torch.no_grad():
        direct = enc(va[1]["image"][None])
    assert torch.allclose(item["features"], direct["features"][0], atol=1e-5)
    FT.EncodedDataset(va, enc)
    assert len(FT._MEMO) == 1  # the same crops and weights: stored once
    aug = A.InterSHTorchDataset(samples[:4], 32, train=True)
    with pytest.raises(ValueError, match="augments"):
        FT.EncodedDataset(aug, enc)


def test_a_second_training_into_the_same_folder_is_refused(samples, tmp_path):
    from handmesh_tutorial._io import single_writer
    from handmesh_tutorial.train.loop import TRAIN_LOCK

    out = tmp_path / "run"
    out.mkdir()
    with single_writer(out / TRAIN_LOCK, "held"), pytest.raises(RuntimeError,
                                                                 match="run.*training"):
        _run(samples, out, epochs=1)
    assert not (out / "checkpoint_last.pt").exists()  # nothing written by the refused run
    _run(samples, out, epochs=1)  # the lock is free again: the same folder trains
    assert (out / "checkpoint_last.pt").exists()


def test_train_only_the_decoder_keeps_every_other_weight(samples, tmp_path):
    """Issue 54: a decoder-only run; every weight and statistic outside ``decoder`` is as built."""
    with pytest.raises(ValueError, match="at least one part"):
        T.TrainConfig(train_only=())
    res = _run(samples, tmp_path / "dec", train_only=("decoder",), epochs=1)
    cfg = T.TrainConfig(**TINY)
    torch.manual_seed(cfg.seed)
    start = T.build_model_from_config(cfg, T.resolve_template(None)).state_dict()
    got = res.model.state_dict()
    moved = {k for k in start if not torch.equal(got[k], start[k])}
    assert moved and all(k.startswith("decoder.") for k in moved), sorted(moved)[:5]
    assert any(k.startswith("decoder.") and k.endswith("weight") for k in moved)
    ck = torch.load(res.checkpoint, weights_only=True)
    assert ck["config"]["train_only"] == ["decoder"]
    assert T.TrainConfig.from_dict(ck["config"]).train_only == ("decoder",)
    with pytest.raises(ValueError, match=r"does not have; its parts are \['decoder', 'encoder'"):
        _run(samples, tmp_path / "bad", train_only=("decodr",), epochs=1)
