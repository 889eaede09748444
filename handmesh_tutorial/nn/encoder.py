"""Image encoders written in the library: ResNet-10/18/34/50 and a small HRNet (W18-small-like).

Paper section "Multi-path Mesh Decoder" (the CNN encoder) and Table 1 (ResNet50, HRNet18/48
backbones). torchvision is not a dependency (no CPU build here, and it would pull CUDA), so the
networks are written out with **torchvision's module names** (ResNet) and the **official
HRNet-Image-Classification / timm names** (HRNet). A user who has pretrained weights can load them
with [`load_torchvision_state_dict`][handmesh_tutorial.nn.encoder.load_torchvision_state_dict] (key
names mapped, shapes checked); nothing is downloaded.

Every encoder maps images ``(B, 3, H, W)`` to a global feature vector ``(B, D)`` (global average
pooling of the last feature map); ``encoder.out_features`` is ``D``. Any ``H, W >= 32`` work.

The HRNet here follows the official classification network (stem, bottleneck layer1, stages 2-4
with parallel branches and fusion, the "incre/downsamp/final" head to 2048 features) with the
configuration of ``hrnet_w18_small_v2`` by default: fewer modules and blocks than the full W18
(2 blocks per branch, 1/3/2 modules in stages 2/3/4 instead of 4 blocks and 1/4/3 modules).
Pass ``config=HRNET_W18`` for the full W18 layout.

ResNet-10 (ResNet-18 with one basic block per stage instead of two; not a torchvision network,
so there are no torchvision weights for it) is the CPU choice: without pretrained weights it
leaves the "mean hand" plateau of from-scratch training in fewer steps than ResNet-18 and each
step costs less (docs page "Why the paper starts from pretrained weights", ``benchmarks/model.py``).

Taught in notebook 08 ("Training"); notebook 07 (section 4) prints the stage shapes of the
shipped network's ResNet-10.

"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import nn

__all__ = [
    "BasicBlock", "Bottleneck", "ResNet", "resnet10", "resnet18", "resnet34", "resnet50", "HRNet",
    "hrnet_w18_small", "build_encoder", "ENCODERS", "load_torchvision_state_dict",
]


def _conv3x3(cin: int, cout: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 3, stride, 1, bias=False)


class BasicBlock(nn.Module):
    """ResNet basic block (two 3x3 convs), torchvision layout and names.

    Args:
        inplanes: input channels.
        planes: output channels.
        stride: stride of the first conv.
        downsample: shortcut module (``None`` = identity).

    Shapes:
        ``(B, inplanes, H, W) -> (B, planes, H/stride, W/stride)``.
    """

    expansion = 1

    def __init__(self, inplanes: int, planes: int, stride: int = 1,
                 downsample: nn.Module | None = None):
        super().__init__()
        self.conv1 = _conv3x3(inplanes, planes, stride)
        self.bn1 = nn.BatchNorm2d(planes)
        self.relu = nn.ReLU(inplace=True)
        self.conv2 = _conv3x3(planes, planes)
        self.bn2 = nn.BatchNorm2d(planes)
        self.downsample = downsample

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Residual forward pass."""
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return self.relu(out + identity)


class Bottleneck(nn.Module):
    """ResNet bottleneck block (1x1, 3x3 with the stride, 1x1 x4), torchvision layout and names.

    Args:
        inplanes: input channels.
        planes: bottleneck width; output has ``4 * planes`` channels.
        stride: stride of the 3x3 conv (ResNet v1.5, as torchvision).
        downsample: shortcut module (``None`` = identity).

    Shapes:
        ``(B, inplanes, H, W) -> (B, 4 * planes, H/stride, W/stride)``.
    """

    expansion = 4

    def __init__(self, inplanes: int, planes: int, stride: int = 1,
                 downsample: nn.Module | None = None):
        super().__init__()
        self.conv1 = nn.Conv2d(inplanes, planes, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(planes)
        self.conv2 = _conv3x3(planes, planes, stride)
        self.bn2 = nn.BatchNorm2d(planes)
        self.conv3 = nn.Conv2d(planes, planes * 4, 1, bias=False)
        self.bn3 = nn.BatchNorm2d(planes * 4)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = downsample

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Residual forward pass."""
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.relu(self.bn2(self.conv2(out)))
        out = self.bn3(self.conv3(out))
        return self.relu(out + identity)


def _make_layer(block, inplanes: int, planes: int, blocks: int, stride: int = 1) -> nn.Sequential:
    downsample = None
    if stride != 1 or inplanes != planes * block.expansion:
        downsample = nn.Sequential(
            nn.Conv2d(inplanes, planes * block.expansion, 1, stride, bias=False),
            nn.BatchNorm2d(planes * block.expansion))
    layers = [block(inplanes, planes, stride, downsample)]
    layers += [block(planes * block.expansion, planes) for _ in range(1, blocks)]
    return nn.Sequential(*layers)


def _init_weights(module: nn.Module) -> None:
    for m in module.modules():
        if isinstance(m, nn.Conv2d):
            nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
        elif isinstance(m, nn.BatchNorm2d):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)


class ResNet(nn.Module):
    """ResNet feature extractor (torchvision architecture and names, no ``fc``).

    Args:
        block: [`BasicBlock`][handmesh_tutorial.nn.encoder.BasicBlock] or
            [`Bottleneck`][handmesh_tutorial.nn.encoder.Bottleneck].
        layers: blocks per stage, e.g. ``(2, 2, 2, 2)`` for ResNet-18.

    Attributes:
        out_features: ``D`` (512 for basic blocks, 2048 for bottlenecks).

    Shapes:
        ``(B, 3, H, W) -> (B, D)``.
    """

    def __init__(self, block, layers):
        super().__init__()
        self.conv1 = nn.Conv2d(3, 64, 7, 2, 3, bias=False)
        self.bn1 = nn.BatchNorm2d(64)
        self.relu = nn.ReLU(inplace=True)
        self.maxpool = nn.MaxPool2d(3, 2, 1)
        self.layer1 = _make_layer(block, 64, 64, layers[0])
        self.layer2 = _make_layer(block, 64 * block.expansion, 128, layers[1], 2)
        self.layer3 = _make_layer(block, 128 * block.expansion, 256, layers[2], 2)
        self.layer4 = _make_layer(block, 256 * block.expansion, 512, layers[3], 2)
        self.avgpool = nn.AdaptiveAvgPool2d(1)
        self.out_features = 512 * block.expansion
        _init_weights(self)

    def forward_features(self, images: torch.Tensor) -> torch.Tensor:
        """The last feature map ``(B, D, H/32, W/32)``."""
        return self.forward_stages(images)[-1]

    def forward_stages(self, images: torch.Tensor) -> list[torch.Tensor]:
        """The four stage outputs, strides 4, 8, 16, 32 (``D/8``, ``D/4``, ``D/2``, ``D``
        channels)."""
        x = self.maxpool(self.relu(self.bn1(self.conv1(images))))
        out = []
        for layer in (self.layer1, self.layer2, self.layer3, self.layer4):
            x = layer(x)
            out.append(x)
        return out

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Args: images ``(B, 3, H, W)``. Returns the pooled features ``(B, D)``."""
        _check_images(images)
        return torch.flatten(self.avgpool(self.forward_features(images)), 1)


def resnet18() -> ResNet:
    """ResNet-18 features, D = 512 (11,176,512 parameters)."""
    return ResNet(BasicBlock, (2, 2, 2, 2))


def resnet10() -> ResNet:
    """ResNet-10 features (one basic block per stage), D = 512 (4,905,792 parameters)."""
    return ResNet(BasicBlock, (1, 1, 1, 1))


def resnet34() -> ResNet:
    """ResNet-34 features, D = 512 (21,284,672 parameters)."""
    return ResNet(BasicBlock, (3, 4, 6, 3))


def resnet50() -> ResNet:
    """ResNet-50 features, D = 2048 (23,508,032 parameters)."""
    return ResNet(Bottleneck, (3, 4, 6, 3))


def _check_images(images: torch.Tensor) -> None:
    if images.dim() != 4 or images.shape[1] != 3:
        raise ValueError(f"expected images (B, 3, H, W), got {tuple(images.shape)}")
    if min(images.shape[2:]) < 32:
        raise ValueError(f"images must be at least 32x32 pixels, got {tuple(images.shape[2:])}")


# ----------------------------------------------------------------------------------------------
# HRNet (classification variant, official names)
# ----------------------------------------------------------------------------------------------

HRNET_W18_SMALL_V2 = {
    "stem_blocks": 2,
    "stages": ((1, (2, 2), (18, 36)), (3, (2, 2, 2), (18, 36, 72)),
               (2, (2, 2, 2, 2), (18, 36, 72, 144))),
}
"""``hrnet_w18_small_v2`` layout: per stage (num_modules, num_blocks per branch, channels)."""
HRNET_W18 = {
    "stem_blocks": 4,
    "stages": ((1, (4, 4), (18, 36)), (4, (4, 4, 4), (18, 36, 72)),
               (3, (4, 4, 4, 4), (18, 36, 72, 144))),
}
"""Full ``hrnet_w18`` layout (4 blocks per branch; 1, 4, 3 modules)."""
_HEAD_CHANNELS = (32, 64, 128, 256)


class _HighResolutionModule(nn.Module):
    # Parallel branches of basic blocks, then HRNet's fusion (official names: branches,
    # fuse_layers; None where the official code has None).
    def __init__(self, in_channels, num_blocks, channels, multi_scale_output=True):
        super().__init__()
        n = len(channels)
        self.branches = nn.ModuleList()
        for i in range(n):
            self.branches.append(_make_layer(BasicBlock, in_channels[i], channels[i],
                                             num_blocks[i]))
        self.fuse_layers = nn.ModuleList()
        for i in range(n if multi_scale_output else 1):
            row = nn.ModuleList()
            for j in range(n):
                if j > i:
                    row.append(nn.Sequential(nn.Conv2d(channels[j], channels[i], 1, bias=False),
                                             nn.BatchNorm2d(channels[i]),
                                             nn.Upsample(scale_factor=2 ** (j - i),
                                                         mode="nearest")))
                elif j == i:
                    row.append(None)
                else:
                    steps = []
                    for k in range(i - j):
                        last = k == i - j - 1
                        cout = channels[i] if last else channels[j]
                        layer = [_conv3x3(channels[j], cout, 2), nn.BatchNorm2d(cout)]
                        if not last:
                            layer.append(nn.ReLU(inplace=True))
                        steps.append(nn.Sequential(*layer))
                    row.append(nn.Sequential(*steps))
            self.fuse_layers.append(row)
        self.relu = nn.ReLU(inplace=False)

    def forward(self, xs):
        xs = [b(x) for b, x in zip(self.branches, xs, strict=True)]
        if len(xs) == 1:
            return xs
        outs = []
        for row in self.fuse_layers:
            y = None
            for j, (f, x) in enumerate(zip(row, xs, strict=True)):
                z = x if f is None else f(x)
                if z.shape[-2:] != xs[len(outs)].shape[-2:]:  # odd sizes: crop the upsampling
                    z = z[..., :xs[len(outs)].shape[-2], :xs[len(outs)].shape[-1]]
                y = z if j == 0 else y + z
            outs.append(self.relu(y))
        return outs


class HRNet(nn.Module):
    """HRNet classification backbone, feature version (official / timm names, no classifier).

    Stem (two stride-2 3x3 convs, 64 channels), ``layer1`` (bottlenecks, 256 channels),
    ``transition1..3`` + ``stage2..4`` (parallel resolutions with repeated fusion), then the
    classification head's ``incre_modules`` / ``downsamp_modules`` / ``final_layer`` to 2048
    channels and global average pooling.

    Args:
        config: layout dict like
            [`HRNET_W18_SMALL_V2`][handmesh_tutorial.nn.encoder.HRNET_W18_SMALL_V2] (default) or
            [`HRNET_W18`][handmesh_tutorial.nn.encoder.HRNET_W18].

    Attributes:
        out_features: ``D = 2048``.

    Shapes:
        ``(B, 3, H, W) -> (B, 2048)``.
    """

    def __init__(self, config: Mapping | None = None):
        super().__init__()
        config = HRNET_W18_SMALL_V2 if config is None else config
        self.conv1 = nn.Conv2d(3, 64, 3, 2, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(64)
        self.conv2 = nn.Conv2d(64, 64, 3, 2, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(64)
        self.relu = nn.ReLU(inplace=True)
        self.layer1 = _make_layer(Bottleneck, 64, 64, config["stem_blocks"])
        pre = [256]
        for s, (modules, blocks, channels) in enumerate(config["stages"], start=2):
            setattr(self, f"transition{s - 1}", self._transition(pre, list(channels)))
            # The classification net keeps every resolution to the end (multi_scale_output=True
            # in all modules), unlike the pose net, because its head reads all branches.
            mods = [_HighResolutionModule(list(channels), blocks, channels)
                    for _ in range(modules)]
            setattr(self, f"stage{s}", nn.Sequential(*mods))
            pre = list(channels)
        self.incre_modules = nn.ModuleList(
            _make_layer(Bottleneck, c, h, 1)
            for c, h in zip(pre, _HEAD_CHANNELS[:len(pre)], strict=True))
        self.downsamp_modules = nn.ModuleList(
            nn.Sequential(nn.Conv2d(_HEAD_CHANNELS[i] * 4, _HEAD_CHANNELS[i + 1] * 4, 3, 2, 1),
                          nn.BatchNorm2d(_HEAD_CHANNELS[i + 1] * 4), nn.ReLU(inplace=True))
            for i in range(len(pre) - 1))
        self.final_layer = nn.Sequential(nn.Conv2d(_HEAD_CHANNELS[len(pre) - 1] * 4, 2048, 1),
                                         nn.BatchNorm2d(2048), nn.ReLU(inplace=True))
        self.avgpool = nn.AdaptiveAvgPool2d(1)
        self.out_features = 2048
        self.num_stages = len(config["stages"])
        _init_weights(self)

    @staticmethod
    def _transition(pre, cur) -> nn.ModuleList:
        layers = nn.ModuleList()
        for i, c in enumerate(cur):
            if i < len(pre):
                layers.append(None if pre[i] == c else nn.Sequential(
                    _conv3x3(pre[i], c), nn.BatchNorm2d(c), nn.ReLU(inplace=True)))
            else:
                steps = []
                for j in range(i + 1 - len(pre)):
                    cin = pre[-1] if j == 0 else c
                    cout = c if j == i - len(pre) else cin
                    steps.append(nn.Sequential(_conv3x3(cin, cout, 2), nn.BatchNorm2d(cout),
                                               nn.ReLU(inplace=True)))
                layers.append(nn.Sequential(*steps))
        return layers

    def forward_features(self, images: torch.Tensor) -> list[torch.Tensor]:
        """The branch feature maps after the last stage, highest resolution first."""
        x = self.relu(self.bn1(self.conv1(images)))
        x = self.relu(self.bn2(self.conv2(x)))
        xs = [self.layer1(x)]
        for s in range(2, self.num_stages + 2):
            trans = getattr(self, f"transition{s - 1}")
            new = []
            for i, t in enumerate(trans):
                src = xs[i] if i < len(xs) else xs[-1]
                new.append(src if t is None else t(src))
            xs = getattr(self, f"stage{s}")(new)
        return xs

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Args: images ``(B, 3, H, W)``. Returns the pooled features ``(B, 2048)``."""
        _check_images(images)
        xs = self.forward_features(images)
        y = self.incre_modules[0](xs[0])
        for i, down in enumerate(self.downsamp_modules):
            z = down(y)
            x = self.incre_modules[i + 1](xs[i + 1])
            h, w = min(z.shape[-2], x.shape[-2]), min(z.shape[-1], x.shape[-1])
            y = x[..., :h, :w] + z[..., :h, :w]
        return torch.flatten(self.avgpool(self.final_layer(y)), 1)


def hrnet_w18_small() -> HRNet:
    """HRNet-W18-small-v2 features, D = 2048 (see module docstring for the layout)."""
    return HRNet(HRNET_W18_SMALL_V2)


ENCODERS = {"resnet10": resnet10, "resnet18": resnet18, "resnet34": resnet34, "resnet50": resnet50,
            "hrnet18": hrnet_w18_small, "hrnet_w18_small": hrnet_w18_small}
"""Encoder names accepted by [`build_encoder`][handmesh_tutorial.nn.encoder.build_encoder] and
``build_model(encoder=...)``."""


def build_encoder(name: str) -> nn.Module:
    """An encoder by name.

    Args:
        name: one of [`ENCODERS`][handmesh_tutorial.nn.encoder.ENCODERS] (``resnet10``,
            ``resnet18``, ``resnet34``, ``resnet50``, ``hrnet18``).

    Returns:
        ``nn.Module`` mapping ``(B, 3, H, W)`` to ``(B, D)``, with attribute ``out_features``.

    Raises:
        ValueError: unknown name.
    """
    if name not in ENCODERS:
        raise ValueError(f"unknown encoder {name!r}; expected one of {', '.join(ENCODERS)}")
    return ENCODERS[name]()


_IGNORED_PREFIXES = ("fc.", "classifier.", "head.fc.", "head.")


def load_torchvision_state_dict(encoder: nn.Module, state_dict: Mapping[str, torch.Tensor],
                                strict: bool = True) -> list[str]:
    """Load pretrained weights with torchvision (ResNet) or timm / official (HRNet) key names.

    Maps the names (strips ``module.`` and ``model.``/``backbone.`` prefixes left by
    ``DataParallel`` or wrappers, drops classification heads ``fc.*``/``classifier.*``, skips
    ``num_batches_tracked``), checks every shape, then copies the tensors. Nothing is downloaded:
    get the file yourself and pass ``torch.load(path, weights_only=True)``.

    Args:
        encoder: a [`ResNet`][handmesh_tutorial.nn.encoder.ResNet] or
            [`HRNet`][handmesh_tutorial.nn.encoder.HRNet] from this module.
        state_dict: mapping name -> tensor.
        strict: raise if an encoder parameter or buffer has no entry (otherwise keep its value).

    Returns:
        The names (after mapping) of entries that were ignored (classification heads).

    Raises:
        ValueError: a tensor's shape differs from the encoder's (names both shapes), a key is
            unknown, or (``strict``) keys are missing.
    """
    own = encoder.state_dict()
    mapped: dict[str, torch.Tensor] = {}
    ignored: list[str] = []
    unknown: list[str] = []
    for key, value in state_dict.items():
        name = key
        for prefix in ("module.", "model.", "backbone.", "encoder."):
            if name.startswith(prefix):
                name = name[len(prefix):]
        if name.endswith("num_batches_tracked") and name not in own:
            continue
        if name.startswith(_IGNORED_PREFIXES):
            ignored.append(name)
            continue
        if name not in own:
            unknown.append(key)
            continue
        if tuple(value.shape) != tuple(own[name].shape):
            raise ValueError(f"shape mismatch for {key!r} (-> {name!r}): checkpoint has "
                             f"{tuple(value.shape)}, encoder expects {tuple(own[name].shape)}; "
                             "is this the right architecture?")
        mapped[name] = value
    if unknown:
        raise ValueError(f"{len(unknown)} keys do not match the encoder, e.g. {unknown[:5]}")
    missing = [k for k in own if k not in mapped and not k.endswith("num_batches_tracked")]
    if strict and missing:
        raise ValueError(f"{len(missing)} encoder entries are missing from the state dict, "
                         f"e.g. {missing[:5]}")
    with torch.no_grad():
        for name, value in mapped.items():
            own[name].copy_(value.to(own[name].dtype))
    return ignored
