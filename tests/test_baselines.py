"""The frozen-encoder baseline: a closed-form ridge read-out from features to vertices."""


import numpy as np
import pytest
import torch

from handmesh_tutorial import train as T
from handmesh_tutorial.train import baselines as Bl

torch.set_num_threads(1)

TINY = {"image_size": 32, "channels": (4, 4, 8, 8, 8), "latent_channels": 8, "threads": 1,
        "progress": False, "durable": False}


def _problem(n=40, d=6, v=5, seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, d)) * rng.uniform(0.1, 10.0, size=d) + rng.normal(size=d)
    w = rng.normal(size=(d, 3 * v))
    y = (x @ w + rng.normal(size=3 * v) + noise * rng.normal(size=(n, 3 * v))).reshape(n, v, 3)
    return x, y


@pytest.mark.parametrize("alpha", [1e-3, 0.1, 2.0])
def test_ridge_equals_least_squares_on_the_augmented_system(alpha):
    """Ridge with an unpenalised intercept on standardised features is the least-squares solution
    of [X_s; sqrt(N alpha) I] W = [Y_c; 0] (the textbook identity), solved here by numpy."""
    x, y = _problem(noise=0.3)
    fit = Bl.fit_linear_readout(x, y, alpha)
    n, d = x.shape
    xs = (x - x.mean(0)) / x.std(0)
    yc = y.reshape(n, -1) - y.reshape(n, -1).mean(0)
    aug_x = np.vstack([xs, np.sqrt(n * alpha) * np.eye(d)])
    aug_y = np.vstack([yc, np.zeros((d, yc.shape[1]))])
    ws = np.linalg.lstsq(aug_x, aug_y, rcond=None)[0]
    want = (xs @ ws + y.reshape(n, -1).mean(0)).reshape(y.shape)
    np.testing.assert_allclose(fit.predict(x), want, atol=1e-9)
    assert fit.alpha == alpha
    # a penalty shrinks: the fitted values' spread falls as alpha grows
    assert np.std(Bl.fit_linear_readout(x, y, 10 * alpha).predict(x)) < np.std(fit.predict(x))


def test_alpha_zero_is_ordinary_least_squares_and_recovers_an_exact_map():
    x, y = _problem(noise=0.0)
    fit = Bl.fit_linear_readout(torch.as_tensor(x), torch.as_tensor(y), 0)
    np.testing.assert_allclose(fit.predict(x), y, atol=1e-9)  # exact linear data, exact fit
    x2, y2 = _problem(noise=0.5, seed=1)
    design = np.c_[x2, np.ones(len(x2))]
    coef = np.linalg.lstsq(design, y2.reshape(len(x2), -1), rcond=None)[0]
    np.testing.assert_allclose(Bl.fit_linear_readout(x2, y2, 0.0).predict(x2),
                               (design @ coef).reshape(y2.shape), atol=1e-9)


def test_a_constant_feature_column_is_centred_not_divided_by_zero():
    x, y = _problem()
    x[:, 2] = 3.0
    fit = Bl.fit_linear_readout(x, y, 0.1)
    assert np.isfinite(fit.weight).all() and np.isfinite(fit.predict(x)).all()


@pytest.mark.parametrize("features, vertices, alpha, match", [
    (np.zeros(10), np.zeros((10, 5, 3)), 1.0, r"features must be \(N, D\).*\(10,\)"),
    (np.zeros((10, 4)), np.zeros((10, 15)), 1.0, r"vertices must be \(N, V, 3\).*\(10, 15\)"),
    (np.zeros((10, 4)), np.zeros((10, 5, 2)), 1.0, r"vertices must be \(N, V, 3\)"),
    (np.zeros((10, 4)), np.zeros((9, 5, 3)), 1.0, r"10 feature vectors, 9 meshes"),
    (np.zeros((1, 4)), np.zeros((1, 5, 3)), 1.0, r"at least 2 samples, got 1"),
    (np.full((10, 4), np.nan), np.zeros((10, 5, 3)), 1.0, r"features holds 40 non-finite"),
    (np.zeros((10, 4)), np.full((10, 5, 3), np.inf), 1.0, r"vertices hold 150 non-finite"),
    (np.zeros((10, 4)), np.zeros((10, 5, 3)), -1.0, r"alpha must be a finite number >= 0"),
    (np.zeros((10, 4)), np.zeros((10, 5, 3)), float("nan"), r"alpha must be a finite number"),
    (np.zeros((10, 4)), np.zeros((10, 5, 3)), "big", r"alpha must be a finite number"),
])
def test_bad_inputs_are_named(features, vertices, alpha, match):
    with pytest.raises(ValueError, match=match):
        Bl.fit_linear_readout(features, vertices, alpha)


def test_predict_refuses_features_of_another_width():
    x, y = _problem()
    with pytest.raises(ValueError, match=r"features must be \(N, 6\), got \(3, 5\)"):
        Bl.fit_linear_readout(x, y, 1.0).predict(np.zeros((3, 5)))



def test_linear_readout_is_a_network_evaluate_scores(toy_root, tmp_path):
    """Fitted on the training crops' features, chosen on the validation crops, evaluated like a
    network; the network it came from is left as it was."""
    cfg = T.TrainConfig(data=str(toy_root), out_dir=str(tmp_path / "r"), val_fraction=0.25,
                        augment=False, **TINY)
    train_ds, val_ds = T.make_datasets(cfg)
    torch.manual_seed(0)
    net = T.build_model_from_config(cfg)
    before = [p.requires_grad for p in net.encoder.parameters()]
    with pytest.raises(ValueError, match="give alpha, or val_dataset"):
        T.linear_readout(net, train_ds)
    with pytest.raises(ValueError, match="must have an encoder module"):
        T.linear_readout(torch.nn.Linear(2, 2), train_ds, alpha=1.0)
    ro = T.linear_readout(net, train_ds, val_dataset=val_ds, alphas=(1e-2, 1.0))
    assert set(ro.validation) == {1e-2, 1.0} and ro.alpha == min(ro.validation,
                                                                  key=ro.validation.get)
    assert [p.requires_grad for p in net.encoder.parameters()] == before
    assert not any(p.requires_grad for p in ro.parameters())
    # its crops' predictions are the ridge fit's on the same features
    items = [train_ds[i] for i in range(len(train_ds))]
    images = torch.stack([it["image"] for it in items])
    with torch.no_grad():
        feats = net.encoder.eval()(images)
        feats = feats["features"] if isinstance(feats, dict) else feats
        out = ro(images)
    gt = torch.stack([it["vertices"] for it in items])
    fit = T.fit_linear_readout(feats, gt, ro.alpha)
    np.testing.assert_allclose(out["vertices"].numpy(), fit.predict(feats), atol=1e-5)
    assert out["joints"].shape == (len(items), 21, 3)
    ev = T.evaluate(ro, toy_root, image_size=32, progress=False)
    assert ev["num_samples"] == 8 and np.isfinite(ev["per_sample"]["pa_mpjpe"]).all()
    assert ev["baseline"] is not None  # the rest hand beside it: the template came along
