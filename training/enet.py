"""ENet (Paszke, Chaurasia, Kim, Culurciello 2016, "ENet: A Deep Neural Network Architecture
for Real-Time Semantic Segmentation") in PyTorch, laid out like e-lab's Torch7 Cityscapes model
so that its weights (``enet-model.net``) load into it one to one.

The layout (as found in e-lab's ``enet-model.net``; C = num_classes, input N x 3 x H x W with H
and W multiples of 8):

* ``initial``: 3x3/2 convolution 3 -> 13 (bias) next to 2x2/2 max pooling of the input,
  concatenated (conv channels first), then batch norm and PReLU over the 16 channels.
* ``bottleneck1_0`` (downsampling, 16 -> 64), ``bottleneck1_1`` .. ``1_4`` (64, dropout 0.01).
* ``bottleneck2_0`` (downsampling, 64 -> 128), ``bottleneck2_1`` .. ``2_8`` and
  ``bottleneck3_1`` .. ``3_8`` (128, dropout 0.1): regular, dilated 2, asymmetric 5,
  dilated 4, regular, dilated 8, asymmetric 5, dilated 16.
* ``bottleneck4_0`` (upsampling, 128 -> 64, unpooling with ``bottleneck2_0``'s indices),
  ``bottleneck4_1``, ``4_2``; ``bottleneck5_0`` (upsampling, 64 -> 16, ``bottleneck1_0``'s
  indices), ``bottleneck5_1``.
* ``fullconv``: 2x2/2 transposed convolution 16 -> C (bias).

Every bottleneck: extension branch 1x1 (2x2/2 when downsampling) projection to channels/4
(no bias), BN, PReLU, main convolution (3x3 / dilated 3x3 / 1x5 then 5x1 / 3x3/2 transposed with
output padding 1; with bias), BN, PReLU, 1x1 expansion (no bias), BN, spatial dropout (encoder
only); main branch identity, or max pooling plus zero channels appended (downsampling), or 1x1
convolution (no bias), BN and max unpooling (upsampling); the sum goes through a PReLU (e-lab
uses PReLU in the decoder too). Batch norm eps is 1e-3.

For e-lab's Cityscapes model, output channel 0 is "unlabeled" and channel k is Cityscapes
trainId k-1; the input is RGB / 255 (no mean or std).

API:
    build_enet(num_classes=20) -> ENet              (fresh, PyTorch default initialisation)
    build_enet_from_torch7(path) -> ENet            (e-lab weights, eval mode)
    load_torch7_weights(model, root) -> ENet        (copy from a read_torch7 tree, checked)

Torch7's SpatialDropout is not inverted (evaluation multiplies by 1 - p); the loader folds that
factor into the batch norm before each dropout, so the module uses PyTorch's ordinary
(inverted) Dropout2d and computes the same function as the Torch model in both modes.

ONNX: ``torch.onnx.export(model, x, f, opset_version=11)`` works (fixed input size); while
exporting, the downsampling pools, the channel padding and the unpoolings are emitted as plain
ONNX MaxPool (with indices) / Pad / MaxUnpool nodes, which OpenCV 4.6's importer accepts.
"""

from __future__ import annotations

import os
import sys
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from torch7 import TorchObject, read_torch7, table_as_list  # noqa: E402

__all__ = ["ENet", "InitialBlock", "RegularBottleneck", "DownsamplingBottleneck",
           "UpsamplingBottleneck", "build_enet", "build_enet_from_torch7", "load_torch7_weights",
           "BN_EPS"]

BN_EPS = 1e-3  # e-lab's SpatialBatchNormalization eps


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=BN_EPS, momentum=0.1)


class InitialBlock(nn.Module):
    """3x3/2 conv (3 -> out-3 channels) beside a 2x2/2 max pool, concatenated, BN, PReLU."""

    def __init__(self, in_channels: int = 3, out_channels: int = 16):
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels - in_channels, 3, stride=2, padding=1,
                              bias=True)
        self.pool = nn.MaxPool2d(2, stride=2)
        self.bn = _bn(out_channels)
        self.prelu = nn.PReLU(out_channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.prelu(self.bn(torch.cat([self.conv(x), self.pool(x)], dim=1)))

    def parameter_layers(self) -> List[nn.Module]:
        return [self.conv, self.bn, self.prelu]


class RegularBottleneck(nn.Module):
    """Residual bottleneck keeping resolution and channels. ``kind``: "regular" (3x3),
    "dilated" (3x3 with ``dilation``), "asymmetric" (1xk then kx1, k = ``asymmetric``)."""

    def __init__(self, channels: int, internal: Optional[int] = None, kind: str = "regular",
                 dilation: int = 1, asymmetric: int = 5, dropout: float = 0.0):
        super().__init__()
        internal = internal or channels // 4
        self.kind = kind
        self.conv1 = nn.Conv2d(channels, internal, 1, bias=False)
        self.bn1 = _bn(internal)
        self.prelu1 = nn.PReLU(internal)
        if kind == "asymmetric":
            k = asymmetric
            self.conv2 = nn.Sequential(
                nn.Conv2d(internal, internal, (1, k), padding=(0, k // 2), bias=False),
                nn.Conv2d(internal, internal, (k, 1), padding=(k // 2, 0), bias=True))
        elif kind in ("regular", "dilated"):
            d = dilation if kind == "dilated" else 1
            self.conv2 = nn.Conv2d(internal, internal, 3, padding=d, dilation=d, bias=True)
        else:
            raise ValueError(f"unknown bottleneck kind {kind!r}")
        self.bn2 = _bn(internal)
        self.prelu2 = nn.PReLU(internal)
        self.conv3 = nn.Conv2d(internal, channels, 1, bias=False)
        self.bn3 = _bn(channels)
        self.dropout = nn.Dropout2d(dropout) if dropout > 0 else nn.Identity()
        self.out_prelu = nn.PReLU(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        ext = self.prelu1(self.bn1(self.conv1(x)))
        ext = self.prelu2(self.bn2(self.conv2(ext)))
        ext = self.dropout(self.bn3(self.conv3(ext)))
        return self.out_prelu(x + ext)

    def parameter_layers(self) -> List[nn.Module]:
        conv2 = list(self.conv2) if isinstance(self.conv2, nn.Sequential) else [self.conv2]
        return [self.conv1, self.bn1, self.prelu1, *conv2, self.bn2, self.prelu2, self.conv3,
                self.bn3, self.out_prelu]


class DownsamplingBottleneck(nn.Module):
    """Halves the resolution: extension branch starts with a 2x2/2 conv; the main branch is a
    2x2/2 max pool (its indices are returned for the decoder) with zero channels appended."""

    def __init__(self, in_channels: int, out_channels: int, internal: Optional[int] = None,
                 dropout: float = 0.0):
        super().__init__()
        internal = internal or out_channels // 4
        self.in_channels, self.out_channels = in_channels, out_channels
        self.conv1 = nn.Conv2d(in_channels, internal, 2, stride=2, bias=False)
        self.bn1 = _bn(internal)
        self.prelu1 = nn.PReLU(internal)
        self.conv2 = nn.Conv2d(internal, internal, 3, padding=1, bias=True)
        self.bn2 = _bn(internal)
        self.prelu2 = nn.PReLU(internal)
        self.conv3 = nn.Conv2d(internal, out_channels, 1, bias=False)
        self.bn3 = _bn(out_channels)
        self.dropout = nn.Dropout2d(dropout) if dropout > 0 else nn.Identity()
        self.pool = nn.MaxPool2d(2, stride=2, return_indices=True)
        self.out_prelu = nn.PReLU(out_channels)

    def forward(self, x: torch.Tensor):
        """Returns (output, pooling indices, pooled tensor's pre-pooling input)."""
        ext = self.prelu1(self.bn1(self.conv1(x)))
        ext = self.prelu2(self.bn2(self.conv2(ext)))
        ext = self.dropout(self.bn3(self.conv3(ext)))
        if torch.onnx.is_in_onnx_export():
            main, indices = _OnnxMaxPool2x2.apply(x)
        else:
            main, indices = self.pool(x)
        pad = self.out_channels - self.in_channels
        if torch.onnx.is_in_onnx_export():
            main = _OnnxChannelPad.apply(main, pad)
        else:
            main = F.pad(main, (0, 0, 0, 0, 0, pad))
        return self.out_prelu(main + ext), indices, x

    def parameter_layers(self) -> List[nn.Module]:
        return [self.conv1, self.bn1, self.prelu1, self.conv2, self.bn2, self.prelu2,
                self.conv3, self.bn3, self.out_prelu]


class _OnnxChannelPad(torch.autograd.Function):
    """Appends ``pad`` zero channels; exports as one ONNX Pad with constant pads (F.pad's own
    export computes the pads with a chain of ops that OpenCV 4.6's importer rejects)."""

    @staticmethod
    def forward(ctx, x, pad: int):  # noqa: D401
        return F.pad(x, (0, 0, 0, 0, 0, pad))

    @staticmethod
    def symbolic(g, x, pad: int):
        pads = g.op("Constant", value_t=torch.tensor([0, 0, 0, 0, 0, pad, 0, 0],
                                                     dtype=torch.int64))
        return g.op("Pad", x, pads, mode_s="constant")


# Export-only stand-ins (used while torch.onnx.export runs). PyTorch 1.13 cannot export
# max_unpool2d, and its export of max_pool2d_with_indices converts ONNX's indices (running over
# the whole N x C x H x W tensor) to PyTorch's (within each plane) with a 1x1 MaxPool whose
# second output OpenCV 4.6 cannot provide. These two emit a bare ONNX MaxPool with indices and
# a MaxUnpool taking them: consistent in ONNX's convention, and in OpenCV's (plane indices in
# both layers).
class _OnnxMaxPool2x2(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x):  # noqa: D401
        return F.max_pool2d(x, 2, 2, return_indices=True)

    @staticmethod
    def symbolic(g, x):
        return g.op("MaxPool", x, outputs=2, kernel_shape_i=[2, 2], strides_i=[2, 2])


class _OnnxMaxUnpool2x2(torch.autograd.Function):
    @staticmethod
    def forward(ctx, values, indices, pre_pool):  # noqa: D401
        return F.max_unpool2d(values, indices, 2, 2, output_size=pre_pool.shape[-2:])

    @staticmethod
    def symbolic(g, values, indices, pre_pool):
        # Output (2h, 2w) = the pooling input's size (ENet's sizes are even there).
        return g.op("MaxUnpool", values, indices, kernel_shape_i=[2, 2], strides_i=[2, 2])


class UpsamplingBottleneck(nn.Module):
    """Doubles the resolution: extension branch with a 3x3/2 transposed conv (output padding 1);
    main branch 1x1 conv, BN and max unpooling with the matching downsampling's indices."""

    def __init__(self, in_channels: int, out_channels: int, internal: Optional[int] = None):
        super().__init__()
        internal = internal or out_channels // 4
        self.conv1 = nn.Conv2d(in_channels, internal, 1, bias=False)
        self.bn1 = _bn(internal)
        self.prelu1 = nn.PReLU(internal)
        self.conv2 = nn.ConvTranspose2d(internal, internal, 3, stride=2, padding=1,
                                        output_padding=1, bias=True)
        self.bn2 = _bn(internal)
        self.prelu2 = nn.PReLU(internal)
        self.conv3 = nn.Conv2d(internal, out_channels, 1, bias=False)
        self.bn3 = _bn(out_channels)
        self.main_conv = nn.Conv2d(in_channels, out_channels, 1, bias=False)
        self.main_bn = _bn(out_channels)
        self.unpool = nn.MaxUnpool2d(2, stride=2)
        self.out_prelu = nn.PReLU(out_channels)

    def forward(self, x: torch.Tensor, indices: torch.Tensor,
                pre_pool: torch.Tensor) -> torch.Tensor:
        ext = self.prelu1(self.bn1(self.conv1(x)))
        ext = self.prelu2(self.bn2(self.conv2(ext)))
        ext = self.bn3(self.conv3(ext))
        main = self.main_bn(self.main_conv(x))
        if torch.onnx.is_in_onnx_export():
            main = _OnnxMaxUnpool2x2.apply(main, indices, pre_pool)
        else:
            main = self.unpool(main, indices, output_size=pre_pool.shape[-2:])
        return self.out_prelu(main + ext)

    def parameter_layers(self) -> List[nn.Module]:
        return [self.conv1, self.bn1, self.prelu1, self.conv2, self.bn2, self.prelu2,
                self.conv3, self.bn3, self.main_conv, self.main_bn, self.out_prelu]


# Stage 2 / 3 pattern (index 1..8): kind, dilation.
_STAGE23 = [("regular", 1), ("dilated", 2), ("asymmetric", 1), ("dilated", 4),
            ("regular", 1), ("dilated", 8), ("asymmetric", 1), ("dilated", 16)]


class ENet(nn.Module):
    """ENet; forward(x: N x 3 x H x W, H and W multiples of 8) -> N x num_classes x H x W
    logits."""

    def __init__(self, num_classes: int = 20):
        super().__init__()
        self.num_classes = num_classes
        self.initial = InitialBlock(3, 16)
        self.bottleneck1_0 = DownsamplingBottleneck(16, 64, 16, dropout=0.01)
        for i in range(1, 5):
            setattr(self, f"bottleneck1_{i}", RegularBottleneck(64, 16, dropout=0.01))
        self.bottleneck2_0 = DownsamplingBottleneck(64, 128, 32, dropout=0.1)
        for stage in (2, 3):
            for i, (kind, dilation) in enumerate(_STAGE23, start=1):
                setattr(self, f"bottleneck{stage}_{i}",
                        RegularBottleneck(128, 32, kind=kind, dilation=dilation, dropout=0.1))
        self.bottleneck4_0 = UpsamplingBottleneck(128, 64, 16)
        self.bottleneck4_1 = RegularBottleneck(64, 16)
        self.bottleneck4_2 = RegularBottleneck(64, 16)
        self.bottleneck5_0 = UpsamplingBottleneck(64, 16, 4)
        self.bottleneck5_1 = RegularBottleneck(16, 4)
        self.fullconv = nn.ConvTranspose2d(16, num_classes, 2, stride=2, bias=True)

    def stages(self) -> List[Tuple[str, nn.Module]]:
        """(name, block) in forward order."""
        names = (["initial", "bottleneck1_0"] + [f"bottleneck1_{i}" for i in range(1, 5)] +
                 ["bottleneck2_0"] + [f"bottleneck2_{i}" for i in range(1, 9)] +
                 [f"bottleneck3_{i}" for i in range(1, 9)] +
                 ["bottleneck4_0", "bottleneck4_1", "bottleneck4_2", "bottleneck5_0",
                  "bottleneck5_1", "fullconv"])
        return [(n, getattr(self, n)) for n in names]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not torch.jit.is_tracing() and not torch.jit.is_scripting():
            h, w = x.shape[-2:]
            if h % 8 or w % 8:
                raise ValueError(f"ENet input height and width must be multiples of 8, got "
                                 f"{w}x{h}")
        x = self.initial(x)
        x, indices1, pre1 = self.bottleneck1_0(x)
        x = self.bottleneck1_4(self.bottleneck1_3(self.bottleneck1_2(self.bottleneck1_1(x))))
        x, indices2, pre2 = self.bottleneck2_0(x)
        for stage in (2, 3):
            for i in range(1, 9):
                x = getattr(self, f"bottleneck{stage}_{i}")(x)
        x = self.bottleneck4_0(x, indices2, pre2)
        x = self.bottleneck4_2(self.bottleneck4_1(x))
        x = self.bottleneck5_0(x, indices1, pre1)
        x = self.bottleneck5_1(x)
        return self.fullconv(x)


def build_enet(num_classes: int = 20) -> ENet:
    """A fresh ENet with PyTorch's default initialisation (PReLU slopes 0.25)."""
    return ENet(num_classes)


# --- Torch7 weights -----------------------------------------------------------------------

_CONV_TYPES = ("nn.SpatialConvolution", "cudnn.SpatialConvolution", "nn.SpatialConvolutionMM",
               "nn.SpatialDilatedConvolution", "cudnn.SpatialDilatedConvolution")
_FULLCONV_TYPES = ("nn.SpatialFullConvolution", "cudnn.SpatialFullConvolution")
_BN_TYPES = ("nn.SpatialBatchNormalization", "cudnn.SpatialBatchNormalization")
_PRELU_TYPES = ("nn.PReLU",)
_PARAM_TYPES = _CONV_TYPES + _FULLCONV_TYPES + _BN_TYPES + _PRELU_TYPES


class Torch7LoadError(ValueError):
    pass


def _num(m: TorchObject, key: str, default: float = 0.0) -> int:
    v = m.get(key, default)
    return int(v)


def _children(m: TorchObject) -> List[Any]:
    return table_as_list(m.get("modules")) if isinstance(m, TorchObject) else []


def _flatten(m: TorchObject) -> List[TorchObject]:
    """Leaf modules of a Torch container tree, depth first (ConcatTable branches in order)."""
    kids = _children(m)
    if not kids:
        return [m]
    out: List[TorchObject] = []
    for k in kids:
        out.extend(_flatten(k))
    return out


def _array(m: TorchObject, key: str) -> Optional[np.ndarray]:
    v = m.get(key)
    if isinstance(v, np.ndarray) and v.size:
        return v
    return None


def _copy(dst: torch.Tensor, src: np.ndarray, what: str) -> None:
    if tuple(dst.shape) != tuple(src.shape):
        raise Torch7LoadError(f"{what}: shape {tuple(src.shape)} in the file, "
                              f"{tuple(dst.shape)} in the module")
    with torch.no_grad():
        dst.copy_(torch.from_numpy(np.ascontiguousarray(src, dtype=np.float32)))


def _load_layer(layer: nn.Module, t: TorchObject, where: str) -> None:
    tn = t.typename
    if isinstance(layer, nn.Conv2d):
        if tn not in _CONV_TYPES:
            raise Torch7LoadError(f"{where}: expected a convolution, found {tn}")
        expect = dict(kernel=(_num(t, "kH"), _num(t, "kW")), stride=(_num(t, "dH", 1),
                                                                     _num(t, "dW", 1)),
                      padding=(_num(t, "padH"), _num(t, "padW")),
                      dilation=(_num(t, "dilationH", 1), _num(t, "dilationW", 1)),
                      groups=_num(t, "groups", 1))
        have = dict(kernel=layer.kernel_size, stride=layer.stride, padding=layer.padding,
                    dilation=layer.dilation, groups=layer.groups)
        if expect != have:
            raise Torch7LoadError(f"{where}: {tn} {expect} vs module {have}")
        weight = t["weight"]
        if weight.ndim == 2:  # SpatialConvolutionMM stores nOut x (nIn kH kW)
            weight = weight.reshape(layer.weight.shape)
        _copy(layer.weight, weight, where + ".weight")
    elif isinstance(layer, nn.ConvTranspose2d):
        if tn not in _FULLCONV_TYPES:
            raise Torch7LoadError(f"{where}: expected a full convolution, found {tn}")
        expect = dict(kernel=(_num(t, "kH"), _num(t, "kW")), stride=(_num(t, "dH", 1),
                                                                     _num(t, "dW", 1)),
                      padding=(_num(t, "padH"), _num(t, "padW")),
                      output_padding=(_num(t, "adjH"), _num(t, "adjW")))
        have = dict(kernel=layer.kernel_size, stride=layer.stride, padding=layer.padding,
                    output_padding=layer.output_padding)
        if expect != have:
            raise Torch7LoadError(f"{where}: {tn} {expect} vs module {have}")
        # Torch7 SpatialFullConvolution: nInputPlane x nOutputPlane x kH x kW, as PyTorch's.
        _copy(layer.weight, t["weight"], where + ".weight")
    elif isinstance(layer, nn.BatchNorm2d):
        if tn not in _BN_TYPES:
            raise Torch7LoadError(f"{where}: expected batch norm, found {tn}")
        eps = float(t.get("eps", 1e-5))
        if abs(eps - layer.eps) > 1e-12:
            raise Torch7LoadError(f"{where}: eps {eps} in the file, {layer.eps} in the module")
        if not t.get("affine", True) or _array(t, "weight") is None:
            raise Torch7LoadError(f"{where}: non-affine batch norm is not supported")
        _copy(layer.weight, t["weight"], where + ".weight")
        _copy(layer.bias, t["bias"], where + ".bias")
        _copy(layer.running_mean, t["running_mean"], where + ".running_mean")
        _copy(layer.running_var, t["running_var"], where + ".running_var")
        return
    elif isinstance(layer, nn.PReLU):
        if tn not in _PRELU_TYPES:
            raise Torch7LoadError(f"{where}: expected PReLU, found {tn}")
        _copy(layer.weight, t["weight"].reshape(-1), where + ".weight")
        return
    else:
        raise Torch7LoadError(f"{where}: unsupported module {type(layer).__name__}")
    # Convolutions: bias present in both or neither.
    bias = _array(t, "bias")
    if (bias is None) != (layer.bias is None):
        raise Torch7LoadError(f"{where}: bias {'absent' if bias is None else 'present'} in the "
                              f"file but not in the module")
    if bias is not None:
        _copy(layer.bias, bias, where + ".bias")


def _fold_dropout(name: str, block: nn.Module, leaves: List[TorchObject]) -> None:
    """Torch7's SpatialDropout (and nn.Dropout without v2) is not inverted: training drops
    channels without rescaling, evaluation multiplies by (1 - p). PyTorch's Dropout2d drops and
    scales by 1 / (1 - p) in training and is the identity in evaluation. Multiplying the
    preceding batch norm's affine weight and bias by (1 - p) makes the two the same function
    in both modes; the block's dropout rate is set to the file's."""
    drops = [t for t in leaves if t.typename in ("nn.SpatialDropout", "nn.Dropout",
                                                 "nn.VolumetricDropout")]
    if len(drops) > 1:
        raise Torch7LoadError(f"{name}: {len(drops)} dropout layers")
    p = float(drops[0]["p"]) if drops else 0.0
    inverted = bool(drops and drops[0].typename == "nn.Dropout" and drops[0].get("v2", False))
    if p > 0 and not inverted:
        with torch.no_grad():
            block.bn3.weight.mul_(1.0 - p)
            block.bn3.bias.mul_(1.0 - p)
    block.dropout = nn.Dropout2d(p) if p > 0 else nn.Identity()


def _check_block_structure(name: str, block: nn.Module, leaves: List[TorchObject],
                           pools: Dict[int, str]) -> None:
    """Checks the non-parametric layers of a Torch block against the module: pooling and its
    parameters, the channel padding of downsampling blocks, which pooling an unpooling uses,
    dropout rates."""
    types = [t.typename for t in leaves]
    for t in leaves:
        if t.typename == "nn.SpatialMaxPooling":
            k = (_num(t, "kH"), _num(t, "kW"), _num(t, "dH"), _num(t, "dW"), _num(t, "padH"),
                 _num(t, "padW"), bool(t.get("ceil_mode", False)))
            if k != (2, 2, 2, 2, 0, 0, False):
                raise Torch7LoadError(f"{name}: max pooling {k}, expected 2x2/2 floor")
    if isinstance(block, DownsamplingBottleneck):
        pads = [t for t in leaves if t.typename == "nn.Padding"]
        if "nn.SpatialMaxPooling" not in types or len(pads) != 1:
            raise Torch7LoadError(f"{name}: main branch without max pooling and padding")
        p = pads[0]
        pad = _num(p, "pad")
        dim = _num(p, "dim")
        n_input_dim = _num(p, "nInputDim", 0)
        index = _num(p, "index", 1)
        # Channel dim (1 of a 3-d C x H x W sample), zeros appended after the input.
        if not (dim == 1 and n_input_dim == 3 and float(p.get("value", 0.0)) == 0.0 and
                pad == block.out_channels - block.in_channels and index == 1):
            raise Torch7LoadError(f"{name}: Padding {dict((k, v) for k, v in p.fields.items() if isinstance(v, float))} "
                                  f"is not zero channels appended")
        pools[id(next(t for t in leaves if t.typename == "nn.SpatialMaxPooling"))] = name
    if isinstance(block, UpsamplingBottleneck):
        unpools = [t for t in leaves if t.typename == "nn.SpatialMaxUnpooling"]
        if len(unpools) != 1:
            raise Torch7LoadError(f"{name}: expected one SpatialMaxUnpooling")
        source = pools.get(id(unpools[0].get("pooling")))
        expected = {"bottleneck4_0": "bottleneck2_0", "bottleneck5_0": "bottleneck1_0"}[name]
        if source != expected:
            raise Torch7LoadError(f"{name}: unpools with {source}'s indices, expected {expected}")
    allowed = set(_PARAM_TYPES) | {"nn.SpatialMaxPooling", "nn.SpatialMaxUnpooling",
                                   "nn.Padding", "nn.SpatialDropout", "nn.Dropout",
                                   "nn.Identity", "nn.CAddTable", "nn.JoinTable", "nn.ReLU",
                                   "cudnn.ReLU"}
    unknown = [t for t in types if t not in allowed]
    if unknown or any(t in ("nn.ReLU", "cudnn.ReLU") for t in types):
        raise Torch7LoadError(f"{name}: unexpected Torch layers {sorted(set(unknown) or {'ReLU'})}")


def load_torch7_weights(model: ENet, root: TorchObject) -> ENet:
    """Copies e-lab ENet weights from a ``read_torch7`` tree into ``model`` (in place), checking
    layer by layer that the structure matches."""
    if not isinstance(root, TorchObject) or root.typename != "nn.Sequential":
        raise Torch7LoadError("the file's root is not an nn.Sequential")
    top = _children(root)
    stages = model.stages()
    # The initial block is 4 top-level modules in e-lab's file: ConcatTable(conv, pool),
    # JoinTable, BN, PReLU; every other stage is one module.
    if len(top) != len(stages) + 3:
        raise Torch7LoadError(f"{len(top)} top-level modules, expected {len(stages) + 3}")
    groups = [top[0:4]] + [[m] for m in top[4:]]
    pools: Dict[int, str] = {}
    for (name, block), group in zip(stages, groups):
        leaves = [leaf for m in group for leaf in _flatten(m)]
        params = [t for t in leaves if t.typename in _PARAM_TYPES]
        layers = block.parameter_layers() if hasattr(block, "parameter_layers") else [block]
        if len(params) != len(layers):
            raise Torch7LoadError(f"{name}: {len(params)} parametrised Torch layers "
                                  f"({[t.typename for t in params]}), module has {len(layers)}")
        for i, (layer, t) in enumerate(zip(layers, params)):
            _load_layer(layer, t, f"{name}[{i}]")
        if hasattr(block, "dropout"):
            _fold_dropout(name, block, leaves)
        _check_block_structure(name, block, leaves, pools)
    return model


def build_enet_from_torch7(path: str) -> ENet:
    """ENet with the weights of an e-lab Torch7 ENet file (e.g. enet-model.net), in eval mode.
    The number of classes is taken from the file's last layer."""
    root = read_torch7(path)
    last = _children(root)[-1]
    if last.typename not in _FULLCONV_TYPES:
        raise Torch7LoadError(f"last layer is {last.typename}, expected a full convolution")
    model = ENet(num_classes=_num(last, "nOutputPlane"))
    load_torch7_weights(model, root)
    return model.eval()
