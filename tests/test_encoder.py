"""Tests of handmesh_tutorial.nn.encoder: ResNet / HRNet shapes, parameter counts, key mapping."""

import pytest
import torch

from handmesh_tutorial.nn import encoder as enc

torch.set_num_threads(1)


def _count(m):
    return sum(p.numel() for p in m.parameters())


# torchvision's numbers without the 1000-way fc (fc = 512*1000+1000 or 2048*1000+1000)
@pytest.mark.parametrize("name,expected", [("resnet18", 11_689_512 - 513_000),
                                           ("resnet34", 21_797_672 - 513_000),
                                           ("resnet50", 25_557_032 - 2_049_000)])
def test_resnet_parameter_counts_equal_torchvision(name, expected):
    assert _count(enc.build_encoder(name)) == expected


def test_resnet18_and_50_known_counts():
    assert _count(enc.resnet18()) == 11_176_512
    assert _count(enc.resnet50()) == 23_508_032


def test_resnet10_is_resnet18_minus_one_basic_block_per_stage():
    # a BasicBlock(c, c) has two 3x3 convs (9c^2 each, no bias) and two BNs (2c each)
    one_block = sum(18 * c * c + 4 * c for c in (64, 128, 256, 512))
    assert _count(enc.resnet10()) == 11_176_512 - one_block == 4_905_792
    assert [len(getattr(enc.resnet10(), f"layer{i}")) for i in range(1, 5)] == [1, 1, 1, 1]


def test_hrnet_parameter_counts_match_timm_model_cards():
    # timm model cards: hrnet_w18_small_v2 15.6 M, hrnet_w18 21.3 M, with a 2048->1000 classifier
    classifier = 2048 * 1000 + 1000
    assert round((_count(enc.hrnet_w18_small()) + classifier) / 1e6, 1) == 15.6
    assert round((_count(enc.HRNet(enc.HRNET_W18)) + classifier) / 1e6, 1) == 21.3


@pytest.mark.parametrize("name,dim", [("resnet10", 512), ("resnet18", 512), ("resnet50", 2048),
                                      ("hrnet18", 2048)])
def test_encoder_output_shapes(name, dim):
    e = enc.build_encoder(name).eval()
    assert e.out_features == dim
    with torch.no_grad():
        assert e(torch.randn(2, 3, 64, 64)).shape == (2, dim)
        if name == "resnet18":
            assert e(torch.randn(1, 3, 224, 224)).shape == (1, dim)
        if name == "hrnet18":  # odd feature-map sizes are cropped, not an error
            assert e(torch.randn(1, 3, 72, 88)).shape == (1, dim)


def test_encoder_input_errors():
    e = enc.resnet18()
    with pytest.raises(ValueError, match=r"expected images \(B, 3, H, W\)"):
        e(torch.zeros(1, 1, 64, 64))
    with pytest.raises(ValueError, match="at least 32x32"):
        e(torch.zeros(1, 3, 16, 16))
    with pytest.raises(ValueError, match="unknown encoder 'vgg'"):
        enc.build_encoder("vgg")


# Names and shapes of a few entries of torchvision's resnet18().state_dict(), written out here
# independently of this library (122 entries in all, fc included).
TORCHVISION_RESNET18 = {
    "conv1.weight": (64, 3, 7, 7),
    "bn1.running_var": (64,),
    "layer1.0.conv1.weight": (64, 64, 3, 3),
    "layer2.0.downsample.0.weight": (128, 64, 1, 1),
    "layer2.0.downsample.1.num_batches_tracked": (),
    "layer3.1.bn2.bias": (256,),
    "layer4.1.conv2.weight": (512, 512, 3, 3),
    "fc.weight": (1000, 512),
    "fc.bias": (1000,),
}


def _synthetic_torchvision_resnet18(prefix=""):
    """A torchvision-named resnet18 state dict with random values (fc included)."""
    own = enc.resnet18().state_dict()
    g = torch.Generator().manual_seed(0)
    sd = {prefix + k: (torch.randn(v.shape, generator=g) if v.is_floating_point()
                       else torch.tensor(7)) for k, v in own.items()}
    sd[prefix + "fc.weight"] = torch.randn(1000, 512, generator=g)
    sd[prefix + "fc.bias"] = torch.randn(1000, generator=g)
    return sd


def test_state_dict_names_are_torchvision_names():
    sd = _synthetic_torchvision_resnet18()
    assert len(sd) == 122
    for k, shape in TORCHVISION_RESNET18.items():
        assert tuple(sd[k].shape) == shape, k


def test_load_torchvision_state_dict_maps_and_copies():
    sd = _synthetic_torchvision_resnet18(prefix="module.")  # as saved from DataParallel
    e = enc.resnet18()
    ignored = enc.load_torchvision_state_dict(e, sd)
    assert sorted(ignored) == ["fc.bias", "fc.weight"]
    loaded = e.state_dict()
    torch.testing.assert_close(loaded["layer3.1.bn2.bias"], sd["module.layer3.1.bn2.bias"])
    torch.testing.assert_close(loaded["conv1.weight"], sd["module.conv1.weight"])
    assert int(loaded["layer1.0.bn1.num_batches_tracked"]) == 7


def test_load_torchvision_state_dict_errors():
    e = enc.resnet18()
    sd = _synthetic_torchvision_resnet18()
    bad = dict(sd, **{"layer1.0.conv1.weight": torch.zeros(64, 64, 1, 1)})
    with pytest.raises(ValueError, match=r"shape mismatch for 'layer1.0.conv1.weight'.*"
                                         r"\(64, 64, 1, 1\).*\(64, 64, 3, 3\)"):
        enc.load_torchvision_state_dict(e, bad)
    with pytest.raises(ValueError, match="do not match the encoder"):
        enc.load_torchvision_state_dict(e, dict(sd, **{"layer5.0.conv1.weight": torch.zeros(1)}))
    partial = {k: v for k, v in sd.items() if not k.startswith("layer4")}
    with pytest.raises(ValueError, match="missing from the state dict"):
        enc.load_torchvision_state_dict(e, partial)
    before = e.state_dict()["layer4.0.conv1.weight"].clone()
    enc.load_torchvision_state_dict(e, partial, strict=False)
    torch.testing.assert_close(e.state_dict()["layer4.0.conv1.weight"], before)
    with pytest.raises(ValueError, match="shape mismatch"):  # resnet50 weights into resnet18
        enc.load_torchvision_state_dict(e, enc.resnet50().state_dict())


def test_hrnet_uses_official_names_and_loads_own_state_dict():
    h = enc.hrnet_w18_small()
    keys = h.state_dict().keys()
    for k in ("conv2.weight", "layer1.0.conv3.weight", "transition1.1.0.0.weight",
              "stage2.0.branches.1.0.conv1.weight", "stage3.2.fuse_layers.2.0.1.0.weight",
              "stage4.1.fuse_layers.0.3.0.weight", "incre_modules.3.0.conv3.weight",
              "downsamp_modules.2.0.weight", "final_layer.0.weight"):
        assert k in keys, k
    sd = {k: torch.randn_like(v) if v.is_floating_point() else v
          for k, v in h.state_dict().items()}
    sd["classifier.weight"] = torch.zeros(1000, 2048)
    h2 = enc.hrnet_w18_small()
    assert enc.load_torchvision_state_dict(h2, sd) == ["classifier.weight"]
    torch.testing.assert_close(h2.state_dict()["final_layer.0.weight"], sd["final_layer.0.weight"])
