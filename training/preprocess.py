"""The C++ Segmenter's image preparation (perception/segmenter_input.cpp), in numpy: the tone curve,
the per-image colour standardisation and the resize to the network's input. A network is trained
on exactly what it will be given at run time."""

import cv2
import numpy as np

# Cityscapes' colour statistics, RGB 0..255 (perception/model_card.h kCityscapesRgbMean/Std).
CITYSCAPES_RGB_MEAN = (73.16, 82.91, 72.39)
CITYSCAPES_RGB_STD = (47.68, 48.49, 47.74)


def apply_gamma(bgr, gamma):
    """v' = 255 (v / 255)^gamma by a lookup table (applyGamma)."""
    if gamma == 1.0:
        return bgr
    table = np.clip(np.rint(255.0 * (np.arange(256) / 255.0) ** gamma), 0, 255).astype(np.uint8)
    return cv2.LUT(bgr, table)


def standardize_colors(bgr, rgb_mean=CITYSCAPES_RGB_MEAN, rgb_std=CITYSCAPES_RGB_STD):
    """Each channel mapped affinely to the target mean / std (standardizeColors); the targets are
    given in RGB, the image is BGR."""
    mean, std = cv2.meanStdDev(bgr)
    out = np.empty_like(bgr)
    for c in range(3):
        network_channel = 2 - c
        gain = rgb_std[network_channel] / max(float(std[c, 0]), 1.0)
        offset = rgb_mean[network_channel] - gain * float(mean[c, 0])
        out[..., c] = np.clip(np.rint(bgr[..., c].astype(np.float64) * gain + offset), 0, 255)
    return out


def card_colors(bgr, gamma=0.7, standardize=True):
    """What segment() does to an image before resizing it for the network."""
    bgr = apply_gamma(bgr, gamma)
    return standardize_colors(bgr) if standardize else bgr


def resize_to_input(bgr, width, height):
    """pad_to_multiple with a fixed input size: INTER_AREA to width x height."""
    if bgr.shape[1] == width and bgr.shape[0] == height:
        return bgr
    return cv2.resize(bgr, (width, height), interpolation=cv2.INTER_AREA)


def to_tensor_rgb01(bgr_batch):
    """N x H x W x 3 uint8 BGR -> N x 3 x H x W float32 RGB in [0, 1] (blobFromImage with
    scale 1/255 and swapRB)."""
    import torch

    rgb = np.ascontiguousarray(bgr_batch[..., ::-1]).astype(np.float32) / 255.0
    return torch.from_numpy(rgb).permute(0, 3, 1, 2).contiguous()
