"""ESPNetv2 for semantic segmentation, written for this project.

Reference: S. Mehta, M. Rastegari, L. Shapiro, H. Hajishirzi, "ESPNetv2: A Light-weight, Power Efficient, and
General Purpose Convolutional Neural Network", CVPR 2019.

The module tree follows the layout of the authors' EdgeNets release closely enough that its Cityscapes
state_dicts (``espnetv2_s_{1.0,2.0}_city_1024x512.pth``) load with ``strict=True``; the code itself is our own.

Three operations of the original are rewritten so that the exact same graph trains in PyTorch and imports in
OpenCV 4.6's ONNX reader (which the C++ node uses):

* the adaptive average pooling inside the EfficientPyrPool decoder block is computed exactly with fixed
  operations (adaptive pooling is linear, separable and periodic with period ``L_in / gcd(L_in, L_out)``):
  AveragePool when the sizes divide, else a strided grouped Conv + one-hot ConvTranspose for small blocks,
  else block-wise MatMul with a constant averaging matrix; see :func:`fixed_adaptive_avg_pool2d`;
* the channel shuffle followed by the grouped 3x3 convolution of the EfficientPyrPool merge layer is computed
  per branch (one depthwise convolution per pyramid branch, summed), which is the same linear map;
* the zero-padded 3x3/2 average pooling of the strided EESP unit and of the input-reinforcement image pyramid
  is a depthwise convolution with constant 1/9 weights (PyTorch exports a padded AveragePool as a constant
  Pad, which OpenCV 4.6 does not import).

All are the original up to float rounding (see ``check_espnetv2.py``); ``set_reference_mode`` switches a model
back to the literal original operations for comparisons.

Input convention of :class:`NormalizedSegmenter`: Nx3xHxW RGB in [0, 1]; ImageNet mean/std normalisation is done
inside.  Output: NxCxHxW logits at input resolution; for the Cityscapes weights C = 20 = trainIds 0..18 then
background (19).  H and W should be multiples of 32 (16 is the hard minimum of the decoder's skip connections).

This file only needs torch (no cv2).
"""

from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence, Tuple

import torch
import torch.nn as nn
import torch.nn.functional as F

__all__ = [
    "WIDTH_CONFIG",
    "EESPEncoder",
    "EfficientPyrPool",
    "EfficientPWConv",
    "ESPNetv2Segmentation",
    "NormalizedSegmenter",
    "build_espnetv2",
    "build_normalized_espnetv2",
    "load_espnetv2_weights",
    "set_reference_mode",
    "fixed_adaptive_avg_pool2d",
    "IMAGENET_MEAN",
    "IMAGENET_STD",
]

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)

# Output channels of (level1, level2, level3, level4, level5, classifier) for each width scale s (paper, Table 1 /
# section 4.1: the network width grows with s; level1 stays at 32 channels for s >= 1).
WIDTH_CONFIG: Dict[float, List[int]] = {
    0.5: [16, 32, 64, 128, 256, 1024],
    1.0: [32, 64, 128, 256, 512, 1024],
    1.25: [32, 80, 160, 320, 640, 1024],
    1.5: [32, 96, 192, 384, 768, 1024],
    2.0: [32, 128, 256, 512, 1024, 1280],
}

# Number of stride-1 EESP units after the strided unit of levels 3 and 4 (level 5 is not used for segmentation).
_REPEATS = {3: 3, 4: 7}
# Upper bound on the effective kernel size of the dilated branches at each spatial level (section 3.2 of the
# paper: fewer, smaller dilations at coarser levels where the feature map is small).
_RECEPTIVE_LIMIT = [13, 11, 9, 7, 5]
_BRANCHES = 4            # K, the number of parallel dilated branches in each EESP unit
_REINF_CHANNELS = 3      # input reinforcement works on the RGB image


# --------------------------------------------------------------------------------------------------------------
# Small building blocks.  Attribute names (conv/bn/act, cbr, br) are fixed by the pretrained state_dicts.
# --------------------------------------------------------------------------------------------------------------

class ConvBnPReLU(nn.Module):
    """Convolution (no bias) -> BatchNorm -> PReLU, used throughout the encoder (keys ``conv``, ``bn``, ``act``)."""

    def __init__(self, c_in: int, c_out: int, k: int, stride: int = 1, groups: int = 1):
        super().__init__()
        self.conv = nn.Conv2d(c_in, c_out, k, stride=stride, padding=(k - 1) // 2, bias=False, groups=groups)
        self.bn = nn.BatchNorm2d(c_out)
        self.act = nn.PReLU(c_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.act(self.bn(self.conv(x)))


class ConvBn(nn.Module):
    """Convolution (no bias) -> BatchNorm, no activation (keys ``conv``, ``bn``)."""

    def __init__(self, c_in: int, c_out: int, k: int, stride: int = 1, groups: int = 1):
        super().__init__()
        self.conv = nn.Conv2d(c_in, c_out, k, stride=stride, padding=(k - 1) // 2, bias=False, groups=groups)
        self.bn = nn.BatchNorm2d(c_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.bn(self.conv(x))


class BnPReLU(nn.Module):
    """BatchNorm -> PReLU (keys ``bn``, ``act``)."""

    def __init__(self, c: int):
        super().__init__()
        self.bn = nn.BatchNorm2d(c)
        self.act = nn.PReLU(c)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.act(self.bn(x))


class DilatedDepthwise(nn.Module):
    """3x3 depthwise convolution with dilation ``d`` and 'same' padding (key ``conv``)."""

    def __init__(self, c: int, stride: int, d: int):
        super().__init__()
        self.conv = nn.Conv2d(c, c, 3, stride=stride, padding=d, dilation=d, groups=c, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(x)


class SeqConvBnPReLU(nn.Module):
    """Decoder-side Conv -> BN -> PReLU, held in a Sequential named ``cbr`` (keys ``cbr.0/1/2``)."""

    def __init__(self, c_in: int, c_out: int, k: int, groups: int = 1):
        super().__init__()
        self.cbr = nn.Sequential(
            nn.Conv2d(c_in, c_out, k, stride=1, padding=(k - 1) // 2, bias=False, groups=groups),
            nn.BatchNorm2d(c_out),
            nn.PReLU(c_out),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.cbr(x)


class SeqBnPReLU(nn.Module):
    """Decoder-side BN -> PReLU, held in a Sequential named ``br`` (keys ``br.0/1``)."""

    def __init__(self, c: int):
        super().__init__()
        self.br = nn.Sequential(nn.BatchNorm2d(c), nn.PReLU(c))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.br(x)


class AvgPool3x3s2(nn.Module):
    """3x3 average pooling, stride 2, zero padding 1, padding counted (``F.avg_pool2d(x, 3, 2, 1)``), written as
    a depthwise convolution with constant 1/9 weights: PyTorch exports a padded AveragePool as a constant Pad +
    AveragePool, and OpenCV 4.6 does not import that Pad.  The weight is a non-persistent buffer (no
    state_dict entry)."""

    def __init__(self, channels: int):
        super().__init__()
        self.channels = channels
        self.register_buffer("kernel", torch.full((channels, 1, 3, 3), 1.0 / 9.0), persistent=False)
        self.reference = False

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.reference:
            return F.avg_pool2d(x, 3, stride=2, padding=1)
        return F.conv2d(x, self.kernel.to(x.dtype), None, 2, 1, 1, self.channels)


class ChannelShuffle(nn.Module):
    """Channel shuffle with ``groups`` groups (ShuffleNet).  Parameter-free; it only occupies index 1 of
    EfficientPyrPool's ``merge_layer`` and is used by the reference path (the default path folds it into the
    following grouped convolution, see :meth:`EfficientPyrPool._merge`)."""

    def __init__(self, groups: int):
        super().__init__()
        self.groups = groups

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n, c, h, w = x.shape
        x = x.reshape(n, self.groups, c // self.groups, h, w).transpose(1, 2)
        return x.reshape(n, c, h, w)


# --------------------------------------------------------------------------------------------------------------
# Encoder (paper section 3: EESP unit, strided EESP with input reinforcement, EESPNet)
# --------------------------------------------------------------------------------------------------------------

def _branch_dilations(k: int, r_lim: int) -> List[int]:
    """Dilation rates of the K branches: branch i would have an effective kernel 3 + 2i; kernels above the
    level's limit fall back to 3x3; sorted ascending so the hierarchical sums go from fine to coarse."""
    ksizes = sorted(3 + 2 * i if 3 + 2 * i <= r_lim else 3 for i in range(k))
    return [(ks - 1) // 2 for ks in ksizes]


class EESPUnit(nn.Module):
    """Extremely Efficient Spatial Pyramid unit (paper section 3.1, Fig. 1c/d).

    group 1x1 reduction (``proj_1x1``, K groups) -> K parallel 3x3 depthwise dilated convolutions (``spp_dw``)
    -> hierarchical feature fusion (branch i adds branch i-1, removing gridding artefacts) -> concat ->
    BN+PReLU (``br_after_cat``) -> group 1x1 expansion (``conv_1x1_exp``, K groups, BN, no activation).
    Stride 1: residual add of the input, then PReLU (``module_act``).  Stride 2 (inside :class:`StridedEESP`):
    the expansion is returned as is (``module_act`` exists in the weights but is unused).
    """

    def __init__(self, c_in: int, c_out: int, stride: int = 1, k: int = 4, r_lim: int = 7):
        super().__init__()
        n = c_out // k
        if n * k != c_out:
            raise ValueError(f"EESP: {c_out} output channels not divisible by K={k}")
        self.stride = stride
        self.proj_1x1 = ConvBnPReLU(c_in, n, 1, stride=1, groups=k)
        self.spp_dw = nn.ModuleList([DilatedDepthwise(n, stride, d) for d in _branch_dilations(k, r_lim)])
        self.conv_1x1_exp = ConvBn(c_out, c_out, 1, 1, groups=k)
        self.br_after_cat = BnPReLU(c_out)
        self.module_act = nn.PReLU(c_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        reduced = self.proj_1x1(x)
        outs = [self.spp_dw[0](reduced)]
        for branch in self.spp_dw[1:]:
            outs.append(branch(reduced) + outs[-1])
        y = self.conv_1x1_exp(self.br_after_cat(torch.cat(outs, 1)))
        if self.stride == 2:
            return y
        return self.module_act(y + x)


class StridedEESP(nn.Module):
    """Strided EESP with a shortcut connection to the input image (paper section 3.1, Fig. 3).

    concat(3x3/2 average pool of the input, stride-2 EESP with c_out - c_in channels) + input reinforcement:
    the RGB image, average-pooled to the same resolution, through 3x3 conv-BN-PReLU and 1x1 conv-BN
    (``inp_reinf``), added; then PReLU (``act``).
    """

    def __init__(self, c_in: int, c_out: int, k: int = 4, r_lim: int = 9, reinforce: bool = True):
        super().__init__()
        self.eesp = EESPUnit(c_in, c_out - c_in, stride=2, k=k, r_lim=r_lim)
        if reinforce:
            self.inp_reinf = nn.Sequential(
                ConvBnPReLU(_REINF_CHANNELS, _REINF_CHANNELS, 3, 1),
                ConvBn(_REINF_CHANNELS, c_out, 1, 1),
            )
        else:
            self.inp_reinf = None
        self.act = nn.PReLU(c_out)
        self.avg = AvgPool3x3s2(c_in)

    def forward(self, x: torch.Tensor, image_at_out_res: Optional[torch.Tensor] = None) -> torch.Tensor:
        y = torch.cat([self.avg(x), self.eesp(x)], 1)
        if image_at_out_res is not None and self.inp_reinf is not None:
            y = y + self.inp_reinf(image_at_out_res)
        return self.act(y)


class EESPEncoder(nn.Module):
    """EESPNet backbone up to level 4 (paper section 3.2, Table 1), i.e. the ImageNet network without level 5
    and the classifier, as used for segmentation (section 4.2).  Returns the features at 1/2, 1/4, 1/8, 1/16.
    """

    def __init__(self, scale: float = 2.0, input_reinforcement: bool = True):
        super().__init__()
        if scale not in WIDTH_CONFIG:
            raise ValueError(f"ESPNetv2 scale {scale} not in {sorted(WIDTH_CONFIG)}")
        ch = WIDTH_CONFIG[scale]
        self.channels = ch
        self.input_reinforcement = input_reinforcement
        k, r = _BRANCHES, _RECEPTIVE_LIMIT
        self.level1 = ConvBnPReLU(3, ch[0], 3, stride=2)
        self.level2_0 = StridedEESP(ch[0], ch[1], k=k, r_lim=r[0], reinforce=input_reinforcement)
        self.level3_0 = StridedEESP(ch[1], ch[2], k=k, r_lim=r[1], reinforce=input_reinforcement)
        self.level3 = nn.ModuleList([EESPUnit(ch[2], ch[2], 1, k=k, r_lim=r[2]) for _ in range(_REPEATS[3])])
        self.level4_0 = StridedEESP(ch[2], ch[3], k=k, r_lim=r[2], reinforce=input_reinforcement)
        self.level4 = nn.ModuleList([EESPUnit(ch[3], ch[3], 1, k=k, r_lim=r[3]) for _ in range(_REPEATS[4])])
        self.image_pool = AvgPool3x3s2(3)

    def forward(self, x: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        f1 = self.level1(x)                                   # 1/2
        # Image pyramid for input reinforcement: repeated 3x3/2 average pooling of the (normalised) input.
        # (Pooling the 1/4 image once more is the same computation as pooling the full image three times.)
        pyr: List[Optional[torch.Tensor]] = [None, None, None]
        if self.input_reinforcement:
            p = self.image_pool(x)                            # 1/2
            for i in range(3):
                p = self.image_pool(p)                        # 1/4, 1/8, 1/16
                pyr[i] = p
        f2 = self.level2_0(f1, pyr[0])                        # 1/4
        f3 = self.level3_0(f2, pyr[1])                        # 1/8
        for unit in self.level3:
            f3 = unit(f3)
        f4 = self.level4_0(f3, pyr[2])                        # 1/16
        for unit in self.level4:
            f4 = unit(f4)
        return f1, f2, f3, f4


# --------------------------------------------------------------------------------------------------------------
# Export-friendly exact adaptive average pooling
# --------------------------------------------------------------------------------------------------------------

_MATRIX_CACHE: Dict[Tuple[int, int, str, torch.dtype], torch.Tensor] = {}


def _averaging_matrix(l_in: int, l_out: int, device, dtype) -> torch.Tensor:
    """(l_in, l_out) matrix M such that x @ M is 1-D adaptive average pooling of x's last axis (PyTorch's
    window rule: [floor(i*l_in/l_out), ceil((i+1)*l_in/l_out))).  Built from Python numbers, so that under
    ONNX tracing it is one constant and not a recorded sequence of tensor writes."""
    key = (l_in, l_out, str(device), dtype)
    m = _MATRIX_CACHE.get(key)
    if m is None:
        rows = [[0.0] * l_out for _ in range(l_in)]
        for i in range(l_out):
            s = (i * l_in) // l_out
            e = ((i + 1) * l_in + l_out - 1) // l_out
            for r in range(s, e):
                rows[r][i] = 1.0 / (e - s)
        m = torch.tensor(rows, dtype=torch.float64).to(device=device, dtype=dtype)
        _MATRIX_CACHE[key] = m
    return m


def _pool_last_axis(x: torch.Tensor, l_out: int) -> torch.Tensor:
    """Adaptive average pooling of the last axis of a 4-D tensor with a block-wise constant matrix product.
    The window pattern repeats every p = L/g inputs and q = l_out/g outputs (g = gcd), so the axis is cut into
    g blocks of p and each block is multiplied by a small (p, q) matrix."""
    n, c, h, l_in = (int(s) for s in x.shape)
    g = math.gcd(l_in, l_out)
    p, q = l_in // g, l_out // g
    m = _averaging_matrix(p, q, x.device, x.dtype)
    if g == 1:
        return torch.matmul(x, m)
    y = torch.matmul(x.reshape(n, c * h * g, p), m)
    return y.reshape(n, c, h, l_out)


_KERNEL_CACHE: Dict[Tuple, Tuple[torch.Tensor, torch.Tensor]] = {}
_BLOCK_CONV_MAX = 64   # use the conv/deconv form when (ph*pw)*(qh*qw) is at most this, else the matmul form


def _block_kernels(c: int, ph: int, pw: int, qh: int, qw: int, device, dtype) -> Tuple[torch.Tensor, torch.Tensor]:
    """Weights of the conv/deconv form of block-periodic adaptive pooling (ph x pw blocks -> qh x qw blocks):
    a stride-(ph, pw) grouped convolution with c*qh*qw outputs whose filter for output sub-position (a, b) is
    the outer product of the 1-D averaging columns, and a stride-(qh, qw) grouped transposed convolution with
    one-hot filters that puts sub-position (a, b) back in place (a depth-to-space)."""
    key = (c, ph, pw, qh, qw, str(device), dtype)
    k = _KERNEL_CACHE.get(key)
    if k is None:
        ah = _averaging_matrix(ph, qh, "cpu", torch.float64).tolist()
        aw = _averaging_matrix(pw, qw, "cpu", torch.float64).tolist()
        pool = [[[[ah[i][a] * aw[j][b] for j in range(pw)] for i in range(ph)]]
                for a in range(qh) for b in range(qw)] * c
        place = [[[[1.0 if (i == a and j == b) else 0.0 for j in range(qw)] for i in range(qh)]]
                 for a in range(qh) for b in range(qw)] * c
        k = (torch.tensor(pool, dtype=torch.float64).to(device=device, dtype=dtype),
             torch.tensor(place, dtype=torch.float64).to(device=device, dtype=dtype))
        _KERNEL_CACHE[key] = k
    return k


def fixed_adaptive_avg_pool2d(x: torch.Tensor, out_hw: Tuple[int, int]) -> torch.Tensor:
    """Exact equivalent of ``F.adaptive_avg_pool2d(x, out_hw)`` for a 4-D tensor, built only from operations that
    OpenCV 4.6's ONNX importer reads.  Adaptive pooling from L to l is periodic with period p = L/g inputs,
    q = l/g outputs (g = gcd(L, l)), so:

    * both axes divisible (q = 1): one AveragePool with kernel = stride = (h/oh, w/ow);
    * small blocks (e.g. the 3x3 -> 2x2 blocks of the s=1.5 pyramid branch): a strided grouped Conv that
      produces the qh*qw outputs of each block as channels, then a grouped ConvTranspose with one-hot kernels
      that interleaves them back (depth-to-space);
    * large blocks (the s=0.1 branch): AveragePool along the divisible axis if any, then for each other axis a
      MatMul with a constant (p, q) averaging matrix over the reshaped blocks (→ OpenCV InnerProduct; the
      height axis goes through a Transpose).
    The choice depends only on the sizes, so a given input size always runs the same ops in training and in
    the export."""
    c, h, w = int(x.shape[1]), int(x.shape[2]), int(x.shape[3])
    oh, ow = int(out_hw[0]), int(out_hw[1])
    if (oh, ow) == (h, w):
        return x
    if h % oh == 0 and w % ow == 0:
        # (no padding, so count_include_pad is irrelevant; False keeps the exporter from emitting a Pad node)
        return F.avg_pool2d(x, (h // oh, w // ow), stride=(h // oh, w // ow), count_include_pad=False)
    gh, gw = math.gcd(h, oh), math.gcd(w, ow)
    ph, qh, pw, qw = h // gh, oh // gh, w // gw, ow // gw
    if ph * pw * qh * qw <= _BLOCK_CONV_MAX:
        pool, place = _block_kernels(c, ph, pw, qh, qw, x.device, x.dtype)
        y = F.conv2d(x, pool, None, (ph, pw), 0, 1, c)
        return F.conv_transpose2d(y, place, None, (qh, qw), 0, 0, c)
    kh = h // oh if h % oh == 0 else 1
    kw = w // ow if w % ow == 0 else 1
    if kh > 1 or kw > 1:
        x = F.avg_pool2d(x, (kh, kw), stride=(kh, kw), count_include_pad=False)
    if h % oh != 0:
        x = _pool_last_axis(x.transpose(2, 3), oh).transpose(2, 3)
    if w % ow != 0:
        x = _pool_last_axis(x, ow)
    return x


# --------------------------------------------------------------------------------------------------------------
# Decoder (paper section 4.2 / EdgeNets segmentation head)
# --------------------------------------------------------------------------------------------------------------

class EfficientPyrPool(nn.Module):
    """Efficient pyramid pooling block of the segmentation decoder (paper section 4.2, "efficient pyramid
    pooling"; EdgeNets' EfficientPyrPool).

    1x1 CBR projection to ``proj_planes`` (``projection_layer``); for each scale s in (2.0, 1.5, 1.0, 0.5, 0.1) a
    3x3 depthwise convolution (``stages``) applied at size ceil(s*h) x ceil(s*w) (at least 5): bilinear
    up-sampling (align_corners) before and adaptive average pooling back after it for s > 1, adaptive average
    pooling before and bilinear up-sampling after for s < 1; concatenation; ``merge_layer``: one BN+PReLU over all
    branches, channel shuffle, 3x3 group conv (groups = proj_planes, CBR) mixing the branches channel-wise,
    1x1 conv to ``out_planes``; then BN+PReLU (``br``) unless it is the classifier (``last_layer_br=False``,
    whose 1x1 conv has a bias).
    """

    SCALES = (2.0, 1.5, 1.0, 0.5, 0.1)

    def __init__(self, in_planes: int, proj_planes: int, out_planes: int, last_layer_br: bool = True):
        super().__init__()
        self.scales = list(self.SCALES)
        self.proj_planes = proj_planes
        self.reference = False
        self.projection_layer = SeqConvBnPReLU(in_planes, proj_planes, 1)
        self.stages = nn.ModuleList([
            nn.Conv2d(proj_planes, proj_planes, 3, padding=1, bias=False, groups=proj_planes) for _ in self.scales
        ])
        nb = len(self.scales)
        self.merge_layer = nn.Sequential(
            SeqBnPReLU(proj_planes * nb),
            ChannelShuffle(nb),
            SeqConvBnPReLU(proj_planes * nb, proj_planes, 3, groups=proj_planes),
            nn.Conv2d(proj_planes, out_planes, 1, bias=not last_layer_br),
        )
        self.last_layer_br = last_layer_br
        if last_layer_br:
            self.br = SeqBnPReLU(out_planes)

    def _pool(self, x: torch.Tensor, hw: Tuple[int, int]) -> torch.Tensor:
        if self.reference:
            return F.adaptive_avg_pool2d(x, hw)
        return fixed_adaptive_avg_pool2d(x, hw)

    def _merge(self, y: torch.Tensor) -> torch.Tensor:
        """merge_layer[2:] after the joint BN+PReLU.  The shuffle puts channel j of every branch next to each
        other and the group conv (groups = proj_planes, 5 inputs per group) then sums, per channel j, a 3x3
        filter over those 5 branch channels; equivalently, the sum over branches b of a depthwise 3x3
        convolution of branch b with the weights conv.weight[:, b]."""
        cbr = self.merge_layer[2].cbr
        if self.reference:
            z = cbr[0](self.merge_layer[1](y))
        else:
            conv = cbr[0]
            p = self.proj_planes
            z = None
            for b in range(len(self.scales)):
                t = F.conv2d(y[:, b * p:(b + 1) * p], conv.weight[:, b:b + 1], None, 1, conv.padding, 1, p)
                z = t if z is None else z + t
        return self.merge_layer[3](cbr[2](cbr[1](z)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.projection_layer(x)
        h, w = int(x.shape[2]), int(x.shape[3])
        branches = []
        for s, stage in zip(self.scales, self.stages):
            hs, ws = max(int(math.ceil(h * s)), 5), max(int(math.ceil(w * s)), 5)
            if s < 1.0:
                t = self._pool(x, (hs, ws))
                t = F.interpolate(stage(t), size=(h, w), mode="bilinear", align_corners=True)
            elif s > 1.0:
                t = F.interpolate(x, size=(hs, ws), mode="bilinear", align_corners=True)
                t = self._pool(stage(t), (h, w))
            else:
                t = stage(x)
            branches.append(t)
        y = self.merge_layer[0](torch.cat(branches, 1))
        y = self._merge(y)
        return self.br(y) if self.last_layer_br else y


class EfficientPWConv(nn.Module):
    """Encoder-to-decoder merge (EdgeNets' EfficientPWConv): a 3x3 group CBR (groups = gcd(c_in, c_out),
    ``expansion_layer``) scaled channel-wise by sigmoid(1x1 conv(global average pool(x))) (``wt_layer``,
    a squeeze-excitation-like gate)."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__()
        self.wt_layer = nn.Sequential(
            nn.AdaptiveAvgPool2d(1),
            nn.Conv2d(c_in, c_out, 1, bias=False),
            nn.Sigmoid(),
        )
        self.expansion_layer = SeqConvBnPReLU(c_in, c_out, 3, groups=math.gcd(c_in, c_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.expansion_layer(x) * self.wt_layer(x)


def _up_to(x: torch.Tensor, hw: Tuple[int, int]) -> torch.Tensor:
    return F.interpolate(x, size=(int(hw[0]), int(hw[1])), mode="bilinear", align_corners=True)


class ESPNetv2Segmentation(nn.Module):
    """ESPNetv2 segmentation network (paper section 4.2): EESPNet encoder (``base_net``) and a bottom-up decoder
    of EfficientPyrPool blocks at 1/16 (``bu_dec_l1``), 1/8, 1/4 and 1/2 (``bu_dec_l4``, the classifier), each step
    upsampling x2 (bilinear, align_corners), adding the gated encoder feature (``merge_enc_dec_l*``) and
    applying BN+PReLU (``bu_br_l*``); final bilinear (align_corners) upsampling to the input size.
    Expects normalised input (ImageNet mean/std); see :class:`NormalizedSegmenter`."""

    def __init__(self, scale: float = 2.0, num_classes: int = 20, base_dec_planes: int = 16,
                 proj_planes: Optional[int] = None):
        super().__init__()
        self.scale = scale
        self.num_classes = num_classes
        self.base_net = EESPEncoder(scale)
        enc = self.base_net.channels
        dec = [4 * base_dec_planes, 3 * base_dec_planes, 2 * base_dec_planes, num_classes]
        pp = proj_planes if proj_planes is not None else min(num_classes // 2, base_dec_planes)
        self.bu_dec_l1 = EfficientPyrPool(enc[3], pp, dec[0])
        self.bu_dec_l2 = EfficientPyrPool(dec[0], pp, dec[1])
        self.bu_dec_l3 = EfficientPyrPool(dec[1], pp, dec[2])
        self.bu_dec_l4 = EfficientPyrPool(dec[2], pp, dec[3], last_layer_br=False)
        self.merge_enc_dec_l2 = EfficientPWConv(enc[2], dec[0])
        self.merge_enc_dec_l3 = EfficientPWConv(enc[1], dec[1])
        self.merge_enc_dec_l4 = EfficientPWConv(enc[0], dec[2])
        self.bu_br_l2 = nn.Sequential(nn.BatchNorm2d(dec[0]), nn.PReLU(dec[0]))
        self.bu_br_l3 = nn.Sequential(nn.BatchNorm2d(dec[1]), nn.PReLU(dec[1]))
        self.bu_br_l4 = nn.Sequential(nn.BatchNorm2d(dec[2]), nn.PReLU(dec[2]))
        self._init_weights()

    def _init_weights(self) -> None:
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out")
                if m.bias is not None:
                    nn.init.zeros_(m.bias)
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        in_hw = (int(x.shape[2]), int(x.shape[3]))
        f1, f2, f3, f4 = self.base_net(x)
        y = self.bu_dec_l1(f4)
        for skip, merge, br, dec in ((f3, self.merge_enc_dec_l2, self.bu_br_l2, self.bu_dec_l2),
                                     (f2, self.merge_enc_dec_l3, self.bu_br_l3, self.bu_dec_l3),
                                     (f1, self.merge_enc_dec_l4, self.bu_br_l4, self.bu_dec_l4)):
            y = _up_to(y, (2 * int(y.shape[2]), 2 * int(y.shape[3])))
            y = dec(br(merge(skip) + y))
        return _up_to(y, in_hw)


class NormalizedSegmenter(nn.Module):
    """Wraps a segmentation network: input Nx3xHxW RGB in [0, 1], ImageNet mean/std subtracted/divided inside
    (so an ONNX export needs only the 1/255 scaling from the caller), output NxCxHxW logits at input size.
    The wrapper adds no state_dict entries besides the ``net.`` prefix."""

    def __init__(self, net: nn.Module, mean: Sequence[float] = IMAGENET_MEAN, std: Sequence[float] = IMAGENET_STD):
        super().__init__()
        self.net = net
        self.register_buffer("mean", torch.tensor(mean, dtype=torch.float32).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(std, dtype=torch.float32).view(1, 3, 1, 1), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net((x - self.mean) / self.std)


# --------------------------------------------------------------------------------------------------------------
# Construction and weights
# --------------------------------------------------------------------------------------------------------------

def _unwrap_state_dict(obj) -> Dict[str, torch.Tensor]:
    if isinstance(obj, dict):
        for key in ("state_dict", "model_state_dict", "model"):
            if key in obj and isinstance(obj[key], dict):
                obj = obj[key]
                break
    sd = dict(obj)
    for prefix in ("module.", "net."):
        if sd and all(k.startswith(prefix) for k in sd):
            sd = {k[len(prefix):]: v for k, v in sd.items()}
    return sd


def load_espnetv2_weights(model: ESPNetv2Segmentation, path: str, strict: bool = True) -> List[str]:
    """Load an EdgeNets-layout state_dict (possibly wrapped in 'state_dict' or prefixed 'module.'/'net.').
    With strict=False, tensors whose shape differs (e.g. another number of classes) are skipped; returns the
    names that were not loaded."""
    sd = _unwrap_state_dict(torch.load(path, map_location="cpu"))
    if strict:
        model.load_state_dict(sd, strict=True)
        return []
    own = model.state_dict()
    usable = {k: v for k, v in sd.items() if k in own and own[k].shape == v.shape}
    model.load_state_dict(usable, strict=False)
    return sorted(set(own) - set(usable))


def build_espnetv2(scale: float, num_classes: int = 20, weights: Optional[str] = None) -> ESPNetv2Segmentation:
    """ESPNetv2 segmentation network at width scale ``scale`` (0.5, 1.0, 1.25, 1.5, 2.0).  ``weights``: an
    EdgeNets Cityscapes state_dict; loaded strictly when num_classes == 20, otherwise everything but the
    classifier-dependent tensors is loaded (the decoder's projection width is kept at 10 so it transfers).
    Expects normalised input; wrap it in :class:`NormalizedSegmenter` for [0, 1] RGB input."""
    proj = None if num_classes == 20 else 10
    model = ESPNetv2Segmentation(scale, num_classes=num_classes, proj_planes=proj)
    if weights is not None:
        load_espnetv2_weights(model, weights, strict=(num_classes == 20))
    return model


def build_normalized_espnetv2(scale: float, num_classes: int = 20,
                              weights: Optional[str] = None) -> NormalizedSegmenter:
    """:func:`build_espnetv2` wrapped in :class:`NormalizedSegmenter` ([0, 1] RGB in, logits out)."""
    return NormalizedSegmenter(build_espnetv2(scale, num_classes, weights))


def set_reference_mode(model: nn.Module, reference: bool = True) -> nn.Module:
    """Switch every EfficientPyrPool and AvgPool3x3s2 in ``model`` between the export-friendly path (default)
    and the literal original operations (F.adaptive_avg_pool2d, channel shuffle + grouped conv,
    F.avg_pool2d) used as a reference.  Only for comparisons: the reference path does not import in OpenCV."""
    for m in model.modules():
        if isinstance(m, (EfficientPyrPool, AvgPool3x3s2)):
            m.reference = reference
    return model
