"""The Cityscapes networks fine-tuning can start from, each as a module that takes RGB in [0, 1]
(N x 3 x H x W) and returns N x 20 x H x W logits: Cityscapes trainIds 0..18, then void."""

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class BaseNetwork:
    name: str
    description: str
    weights: str  # relative to the shared folder
    build: Callable  # weights path -> torch.nn.Module
    # Whether a parameter name of the built module is the encoder's (the feature extractor that
    # runs at 1/2 to 1/8 or 1/16 scale), not the decoder's: --encoder-lr-scale acts on these.
    is_encoder: Callable  # parameter name -> bool


def _espnetv2(scale):
    def build(path):
        import espnetv2

        return espnetv2.NormalizedSegmenter(espnetv2.build_espnetv2(scale, 20, path))

    return build


def _enet(path):
    import torch

    import enet

    class TrainIdOrder(torch.nn.Module):
        """e-lab's channel 0 is void and channel k trainId k - 1: void moved last."""

        def __init__(self, net):
            super().__init__()
            self.net = net

        def forward(self, x):
            y = self.net(x)
            return torch.cat([y[:, 1:], y[:, :1]], dim=1)

    return TrainIdOrder(enet.build_enet_from_torch7(path))


def _espnetv2_encoder(name):
    return name.startswith("net.base_net.")  # NormalizedSegmenter.net.base_net: the EESPNet


def _enet_encoder(name):
    # ENet's encoder: the initial block and stages 1-3 (4 and 5 upsample: the decoder).
    return name.startswith(("net.initial.", "net.bottleneck1_", "net.bottleneck2_",
                            "net.bottleneck3_"))


_NETWORKS = {
    "espnetv2_s2": BaseNetwork("espnetv2_s2", "ESPNetv2 s=2.0 (Cityscapes, Mehta et al. 2019)",
                               "models/espnetv2-cityscapes/espnetv2_s_2.0_city_1024x512.pth",
                               _espnetv2(2.0), _espnetv2_encoder),
    "espnetv2_s1": BaseNetwork("espnetv2_s1", "ESPNetv2 s=1.0 (Cityscapes, Mehta et al. 2019)",
                               "models/espnetv2-cityscapes/espnetv2_s_1.0_city_1024x512.pth",
                               _espnetv2(1.0), _espnetv2_encoder),
    "enet": BaseNetwork("enet", "the e-lab ENet (Cityscapes, Paszke et al. 2016)",
                        "models/enet-cityscapes/enet-model.net", _enet, _enet_encoder),
}


def names():
    return sorted(_NETWORKS)


def get(name):
    if name not in _NETWORKS:
        raise SystemExit(f"unknown base network '{name}' (one of {', '.join(names())})")
    return _NETWORKS[name]
