"""The four segmentation networks of the paper's comparison, at reduced width.

Backbones: MobileNetV2 (inverted residuals, depthwise separable convolutions) and ShuffleNetV2
(channel split + shuffle). Heads: FCN8s (class scores from the /8, /16 and /32 features, summed
while upsampling), FCN4s (FCN8s plus class scores from the /4 features, for obstacles a few
pixels wide; the new scores start at zero, so an FCN4s warm-started from an FCN8s starts as
nearly that FCN8s) and U-Net (decodes at every stage, /32 -> /16 -> /8 -> /4 -> /2 -> input).

Every backbone returns its features at strides 2, 4, 8, 16 and 32. Upsampling is bilinear to the
exact size of the skip feature, so any input height and width works (the exported graph has dynamic
H and W); multiples of 32 waste nothing.

Networks output NUM_OUTPUTS = 14 logits: channel k is SemanticClass id k + 1 (class 0, unknown,
is never predicted and is ignored in the loss). `ExportWrapper` turns logits into uint8 class ids
inside the graph.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

NUM_CLASSES = 15  # SemanticClass ids 0..14, 0 = unknown
NUM_OUTPUTS = NUM_CLASSES - 1  # the model predicts ids 1..14

CLASS_NAMES = [
    "unknown", "sky", "ground", "building wall", "building rooftop", "small rooftop entrance",
    "skylight", "air vents", "ac-unit", "seating", "air ducts", "water tower", "chimney", "tarp",
    "vegetation",
]

# ImageNet statistics; the Rust crate uses the same (landing_perception::NORMALIZE_*).
MEAN = (0.485, 0.456, 0.406)
STD = (0.229, 0.224, 0.225)

ARCHITECTURES = ("mobilenet_fcn8s", "shufflenet_fcn8s", "mobilenet_unet", "shufflenet_unet",
                 "mobilenet_fcn4s")


def _divisible(v: float, d: int = 8) -> int:
    out = max(d, int(v + d / 2) // d * d)
    if out < 0.9 * v:
        out += d
    return out


def conv_bn(cin: int, cout: int, k: int = 3, stride: int = 1, groups: int = 1, act: bool = True):
    layers: list[nn.Module] = [
        nn.Conv2d(cin, cout, k, stride, k // 2, groups=groups, bias=False),
        nn.BatchNorm2d(cout),
    ]
    if act:
        layers.append(nn.ReLU6(inplace=True) if groups == 1 else nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


# --------------------------------------------------------------------------------------------
# MobileNetV2
# --------------------------------------------------------------------------------------------


class InvertedResidual(nn.Module):
    def __init__(self, cin: int, cout: int, stride: int, expand: int):
        super().__init__()
        hidden = cin * expand
        self.use_res = stride == 1 and cin == cout
        layers: list[nn.Module] = []
        if expand != 1:
            layers.append(conv_bn(cin, hidden, 1))
        layers += [
            nn.Conv2d(hidden, hidden, 3, stride, 1, groups=hidden, bias=False),
            nn.BatchNorm2d(hidden),
            nn.ReLU6(inplace=True),
            conv_bn(hidden, cout, 1, act=False),
        ]
        self.block = nn.Sequential(*layers)

    def forward(self, x):
        y = self.block(x)
        return x + y if self.use_res else y


class MobileNetV2(nn.Module):
    # (expansion, channels, repeats, first stride, stage) from the MobileNetV2 paper; stage -1
    # runs at /2 with the stem, stages 0..3 end at /4, /8, /16, /32.
    SETTINGS = [(1, 16, 1, 1, -1), (6, 24, 2, 2, 0), (6, 32, 3, 2, 1), (6, 64, 4, 2, 2),
                (6, 96, 3, 1, 2), (6, 160, 3, 2, 3), (6, 320, 1, 1, 3)]

    def __init__(self, width: float = 0.5):
        super().__init__()
        cin = _divisible(32 * width)
        self.stem = conv_bn(3, cin, 3, 2)  # /2
        stages: list[list[nn.Module]] = [[], [], [], []]
        self.channels = [0, 0, 0, 0, 0]
        for t, c, n, s, stage in self.SETTINGS:
            cout = _divisible(c * width)
            for i in range(n):
                block = InvertedResidual(cin, cout, s if i == 0 else 1, t)
                if stage < 0:
                    self.stem.append(block)
                else:
                    stages[stage].append(block)
                cin = cout
            self.channels[stage + 1] = cout
        self.stages = nn.ModuleList(nn.Sequential(*s) for s in stages)

    def forward(self, x):
        feats = [self.stem(x)]
        for s in self.stages:
            feats.append(s(feats[-1]))
        return feats  # strides 2, 4, 8, 16, 32


# --------------------------------------------------------------------------------------------
# ShuffleNetV2
# --------------------------------------------------------------------------------------------


def channel_shuffle(x: torch.Tensor, perm: torch.Tensor) -> torch.Tensor:
    # A constant permutation (Gather in ONNX) instead of reshape/transpose: no shape arithmetic.
    return x.index_select(1, perm)


class ShuffleUnit(nn.Module):
    def __init__(self, cin: int, cout: int, stride: int):
        super().__init__()
        self.stride = stride
        branch = cout // 2
        if stride == 2:
            self.left = nn.Sequential(
                conv_bn(cin, cin, 3, 2, groups=cin, act=False),
                conv_bn(cin, branch, 1),
            )
            right_in = cin
        else:
            self.left = None
            right_in = branch
        self.right = nn.Sequential(
            conv_bn(right_in, branch, 1),
            conv_bn(branch, branch, 3, stride, groups=branch, act=False),
            conv_bn(branch, branch, 1),
        )
        # After concatenating [a, b], interleave: a0 b0 a1 b1 ...
        perm = torch.arange(cout).view(2, branch).t().reshape(-1)
        self.register_buffer("perm", perm, persistent=False)
        self.branch = branch

    def forward(self, x):
        if self.stride == 1:
            a, b = x[:, : self.branch], x[:, self.branch:]
            out = torch.cat([a, self.right(b)], 1)
        else:
            out = torch.cat([self.left(x), self.right(x)], 1)
        return channel_shuffle(out, self.perm)


class ShuffleNetV2(nn.Module):
    def __init__(self, width: float = 0.5):
        super().__init__()
        chans = {0.5: [48, 96, 192], 1.0: [116, 232, 464]}.get(width) or [
            _divisible(116 * width * 2) // 2 * 2, _divisible(232 * width * 2) // 2 * 2,
            _divisible(464 * width * 2) // 2 * 2]
        stem_c = 24
        self.stem = conv_bn(3, stem_c, 3, 2)  # /2
        self.pool = nn.MaxPool2d(3, 2, 1)  # /4
        stages = []
        cin = stem_c
        for cout, repeats in zip(chans, (4, 8, 4)):
            units = [ShuffleUnit(cin, cout, 2)] + [ShuffleUnit(cout, cout, 1) for _ in range(repeats - 1)]
            stages.append(nn.Sequential(*units))
            cin = cout
        self.stages = nn.ModuleList(stages)  # /8, /16, /32
        self.channels = [stem_c, stem_c] + chans

    def forward(self, x):
        s2 = self.stem(x)
        s4 = self.pool(s2)
        feats = [s2, s4]
        for s in self.stages:
            feats.append(s(feats[-1]))
        return feats


# --------------------------------------------------------------------------------------------
# Heads
# --------------------------------------------------------------------------------------------


def up_to(x: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, size=ref.shape[-2:], mode="bilinear", align_corners=False)


class FCN8s(nn.Module):
    """Scores from /32 (after a conv7-like block), /16 and /8, summed while upsampling."""

    def __init__(self, channels: list[int], hidden: int = 256):
        super().__init__()
        self.conv7 = nn.Sequential(conv_bn(channels[4], hidden, 1), nn.Dropout2d(0.1))
        self.score32 = nn.Conv2d(hidden, NUM_OUTPUTS, 1)
        self.score16 = nn.Conv2d(channels[3], NUM_OUTPUTS, 1)
        self.score8 = nn.Conv2d(channels[2], NUM_OUTPUTS, 1)

    def forward(self, feats, image):
        x = self.score32(self.conv7(feats[4]))
        x = up_to(x, feats[3]) + self.score16(feats[3])
        x = up_to(x, feats[2]) + self.score8(feats[2])
        return up_to(x, image)


class FCN4s(FCN8s):
    """FCN8s plus scores from the /4 features: the /8 sum is upsampled to /4, the /4 scores added,
    and the result upsampled to the input. The /4 scores are zero-initialised and marked
    `warm_start_skip`: `--init-onnx` from an FCN8s model loads every other convolution. The
    network then starts as that model except for the upsampling path (/8 -> /4 -> input instead
    of /8 -> input: 0.8 % of pixels differ, at class boundaries). Upsampling each path to the input
    separately would start bit for bit identical but costs about 3 ms more per 320x240 frame."""

    def __init__(self, channels: list[int], hidden: int = 256):
        super().__init__(channels, hidden)
        self.score4 = nn.Conv2d(channels[1], NUM_OUTPUTS, 1)
        nn.init.zeros_(self.score4.weight)
        nn.init.zeros_(self.score4.bias)
        self.score4.warm_start_skip = True

    def forward(self, feats, image):
        x = self.score32(self.conv7(feats[4]))
        x = up_to(x, feats[3]) + self.score16(feats[3])
        x = up_to(x, feats[2]) + self.score8(feats[2])
        x = up_to(x, feats[1]) + self.score4(feats[1])
        return up_to(x, image)


class UNetBlock(nn.Module):
    def __init__(self, cin: int, cskip: int, cout: int):
        super().__init__()
        c = cin + cskip
        # Depthwise separable 3x3 keeps the decoder light.
        self.conv = nn.Sequential(conv_bn(c, c, 3, groups=c, act=False), conv_bn(c, cout, 1))

    def forward(self, x, skip):
        return self.conv(torch.cat([up_to(x, skip), skip], 1))


class UNet(nn.Module):
    """Decodes at every stage: /32 -> /16 -> /8 -> /4 -> /2, then classifies and upsamples."""

    def __init__(self, channels: list[int], widths=(96, 64, 32, 24)):
        super().__init__()
        c = channels[4]
        blocks = []
        for skip_c, w in zip(reversed(channels[:4]), widths):
            blocks.append(UNetBlock(c, skip_c, w))
            c = w
        self.blocks = nn.ModuleList(blocks)
        self.classifier = nn.Conv2d(c, NUM_OUTPUTS, 1)

    def forward(self, feats, image):
        x = feats[4]
        for block, skip in zip(self.blocks, reversed(feats[:4])):
            x = block(x, skip)
        return up_to(self.classifier(x), image)


class SegNet(nn.Module):
    def __init__(self, arch: str, width: float = 0.5):
        super().__init__()
        if arch not in ARCHITECTURES:
            raise ValueError(f"unknown arch {arch!r}; one of {ARCHITECTURES}")
        backbone, head = arch.split("_")
        self.arch = arch
        self.width = width
        self.backbone = MobileNetV2(width) if backbone == "mobilenet" else ShuffleNetV2(width)
        ch = self.backbone.channels
        self.head = {"fcn8s": FCN8s, "fcn4s": FCN4s, "unet": UNet}[head](ch)

    def forward(self, x):
        """x: normalised float NCHW. Returns NUM_OUTPUTS logits per pixel at input resolution."""
        return self.head(self.backbone(x), x)


class ExportWrapper(nn.Module):
    """What ships: normalised float NCHW in, uint8 SemanticClass ids [N, H, W] out."""

    def __init__(self, net: SegNet):
        super().__init__()
        self.net = net

    def forward(self, image):
        ids = self.net(image).argmax(1) + 1
        return ids.to(torch.uint8)


def build(arch: str, width: float = 0.5) -> SegNet:
    return SegNet(arch, width)


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())
