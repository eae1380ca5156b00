"""Training-time augmentation at the network's input scale: scale jitter, crops, mirroring and
a residual colour jitter (the card's standardisation has already matched each image's mean and
spread to the training statistics, so what is left to vary is contrast shape, saturation and
small per-channel gains)."""

import cv2
import numpy as np

import labels


def _resize_labels(target, width, height, sparse):
    if sparse:
        import datasets

        return datasets.scatter_sparse(target, width, height)
    return cv2.resize(target, (width, height), interpolation=cv2.INTER_NEAREST)


def _pad_teacher(teacher, pad_h, pad_w):
    """Pads what the base network teaches with 'nothing taught': IGNORE in a label map, zeros
    (a zero mask channel) in a soft target (H x W x C; numpy, as cv2 pads at most 4 channels)."""
    if teacher.ndim == 2:
        return cv2.copyMakeBorder(teacher, 0, pad_h, 0, pad_w, cv2.BORDER_CONSTANT,
                                  value=labels.IGNORE)
    return np.pad(teacher, ((0, pad_h), (0, pad_w), (0, 0)))


def random_crop(sample, teacher_mask_fn, rng, crop_h, crop_w, scale_range=(0.8, 1.25)):
    """(image, target, teacher) crop of crop_h x crop_w after a random rescale and mirror. The
    teacher is an H x W label map or an H x W x C soft target (resized nearest, padded empty)."""
    s = rng.uniform(*scale_range)
    h0, w0 = sample.image.shape[:2]
    h, w = max(8, int(round(h0 * s))), max(8, int(round(w0 * s)))
    image = cv2.resize(sample.image, (w, h),
                       interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
    sparse = sample.kind == "sparse"
    target = _resize_labels(sample.target, w, h, sparse)
    teacher = cv2.resize(teacher_mask_fn(sample), (w, h), interpolation=cv2.INTER_NEAREST)
    pad_h, pad_w = max(0, crop_h - h), max(0, crop_w - w)
    if pad_h or pad_w:
        image = cv2.copyMakeBorder(image, 0, pad_h, 0, pad_w, cv2.BORDER_REFLECT_101)
        target = cv2.copyMakeBorder(target, 0, pad_h, 0, pad_w, cv2.BORDER_CONSTANT,
                                    value=labels.IGNORE)
        teacher = _pad_teacher(teacher, pad_h, pad_w)
        h, w = image.shape[:2]
    y = rng.integers(0, h - crop_h + 1)
    x = rng.integers(0, w - crop_w + 1)
    image = image[y:y + crop_h, x:x + crop_w]
    target = target[y:y + crop_h, x:x + crop_w]
    teacher = teacher[y:y + crop_h, x:x + crop_w]
    if rng.random() < 0.5:
        image, target, teacher = image[:, ::-1], target[:, ::-1], teacher[:, ::-1]
    return jitter_colors(np.ascontiguousarray(image), rng), np.ascontiguousarray(
        target), np.ascontiguousarray(teacher)


def jitter_colors(bgr, rng, gamma_range=(0.8, 1.25), saturation_range=(0.75, 1.25),
                  gain_range=(0.92, 1.08)):
    out = bgr.astype(np.float32) / 255.0
    out = out ** rng.uniform(*gamma_range)
    gray = out.mean(axis=2, keepdims=True)
    out = gray + (out - gray) * rng.uniform(*saturation_range)
    out = out * rng.uniform(*gain_range, size=3).astype(np.float32)
    return np.clip(out * 255.0 + 0.5, 0, 255).astype(np.uint8)
