"""Training-time augmentation at the network's input scale: scale jitter, crops, mirroring, a
residual colour jitter (the card's standardisation has already matched each image's mean and
spread to the training statistics, so what is left to vary is contrast shape, saturation and
small per-channel gains) and, optionally, objects of the rare classes pasted into crops."""

from dataclasses import dataclass

import cv2
import numpy as np

import labels


def _resize_labels(target, width, height, sparse):
    if sparse:
        import datasets

        return datasets.scatter_sparse(target, width, height)
    return cv2.resize(target, (width, height), interpolation=cv2.INTER_NEAREST_EXACT)


def _pad_teacher(teacher, pad_h, pad_w):
    """Pads what the base network teaches with 'nothing taught': IGNORE in a label map, zeros
    (a zero mask channel) in a soft target (H x W x C; numpy, as cv2 pads at most 4 channels)."""
    if teacher.ndim == 2:
        return cv2.copyMakeBorder(teacher, 0, pad_h, 0, pad_w, cv2.BORDER_CONSTANT,
                                  value=labels.IGNORE)
    return np.pad(teacher, ((0, pad_h), (0, pad_w), (0, 0)))


def nearest_window(source, height, width, y, x, crop_h, crop_w):
    """The crop [y, y + crop_h) x [x, x + crop_w) of source resized to height x width by
    cv2.INTER_NEAREST_EXACT, without resizing the rest: the source rows and columns that OpenCV's
    resize reads, picked directly. A soft teacher is 20+ channels: converting and resizing it
    whole for every crop took a third of a crop's time, and a teacher kept on disk
    (teacher_store) is read only where the crop lies."""
    def picks(old, new, start, count):
        # OpenCV's 16-bit fixed point for the source pixel under each output pixel's centre,
        # (i + 1/2) * old / new (plain INTER_NEAREST reads at i * old / new: labels half an
        # output pixel up and left of the image that INTER_AREA / INTER_LINEAR resize).
        step = ((old << 16) + new // 2) // new
        index = (step // 2 - 1 + np.arange(start, start + count, dtype=np.int64) * step) >> 16
        return np.clip(index, 0, old - 1)

    rows = picks(source.shape[0], height, y, crop_h)
    cols = picks(source.shape[1], width, x, crop_w)
    return source[rows[:, None], cols[None, :]]


def random_crop(sample, rng, crop_h, crop_w, teacher_dtype=None, scale_range=(0.8, 1.25),
                paste=None):
    """(image, target, teacher) crop of crop_h x crop_w after a random rescale and mirror. The
    teacher (sample.teacher) is an H x W label map or an H x W x C soft target (resized nearest,
    padded empty), converted to teacher_dtype when given. paste(image, target, teacher, rng), when
    given, changes the crop in place before the mirror and the colour jitter (so that what it
    pastes is mirrored and coloured with the rest)."""
    s = rng.uniform(*scale_range)
    h0, w0 = sample.image.shape[:2]
    h, w = max(8, int(round(h0 * s))), max(8, int(round(w0 * s)))
    image = cv2.resize(sample.image, (w, h),
                       interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
    sparse = sample.kind == "sparse"
    target = _resize_labels(sample.target, w, h, sparse)
    pad_h, pad_w = max(0, crop_h - h), max(0, crop_w - w)
    if pad_h or pad_w:
        teacher = nearest_window(sample.teacher, h, w, 0, 0, h, w)
        image = cv2.copyMakeBorder(image, 0, pad_h, 0, pad_w, cv2.BORDER_REFLECT_101)
        target = cv2.copyMakeBorder(target, 0, pad_h, 0, pad_w, cv2.BORDER_CONSTANT,
                                    value=labels.IGNORE)
        teacher = _pad_teacher(teacher, pad_h, pad_w)
        h, w = image.shape[:2]
    y = rng.integers(0, h - crop_h + 1)
    x = rng.integers(0, w - crop_w + 1)
    image = image[y:y + crop_h, x:x + crop_w]
    target = target[y:y + crop_h, x:x + crop_w]
    if pad_h or pad_w:
        teacher = teacher[y:y + crop_h, x:x + crop_w]
    else:
        teacher = nearest_window(sample.teacher, h, w, y, x, crop_h, crop_w)
    if teacher_dtype is not None:
        teacher = teacher.astype(teacher_dtype)
    if paste is not None:
        # Writing in place is safe: the image and target are windows of their resized copies,
        # the teacher a window picked by index (a copy) or converted; none is the sample's own.
        paste(image, target, teacher, rng)
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


@dataclass
class CutObject:
    """A region of rare-class human labels cut from a dense frame with its bounding box."""
    source: str  # the frame's name, for the log
    image: np.ndarray  # h x w x 3 uint8 BGR
    target: np.ndarray  # h x w uint8 trainIds, IGNORE outside the region


def cut_objects(samples, class_ids, min_pixels=120):
    """Every 8-connected region of the given trainIds in the densely labelled samples (a rider
    and its bicycle are one region) with at least min_pixels pixels: smaller ones are mostly
    stray label pixels (the KITTI semantic frames hold a few pixels of "bus" in every frame)."""
    objects = []
    for s in samples:
        if s.kind != "dense":
            continue
        mask = np.isin(s.target, class_ids)
        if not mask.any():
            continue
        count, regions, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8),
                                                                   connectivity=8)
        for i in range(1, count):
            x, y, w, h, area = stats[i]
            if area < min_pixels:
                continue
            inside = regions[y:y + h, x:x + w] == i
            target = np.where(inside, s.target[y:y + h, x:x + w], labels.IGNORE).astype(np.uint8)
            objects.append(CutObject(s.name, s.image[y:y + h, x:x + w].copy(), target))
    return objects


def paste_objects(image, target, teacher, objects, rng, count, scale_range=(0.8, 1.25)):
    """Simple copy-paste (Ghiasi et al. 2021): count objects drawn from objects, each rescaled
    by a random factor and mirrored at random, written over the crop at a random place where it
    fits (skipped where it does not). The pasted pixels take the object's human labels, and the
    teacher teaches nothing there (IGNORE in a label map, weight 0 in the last channel of a soft
    target): its view is of the background the object now hides. In place."""
    height, width = target.shape
    for _ in range(count):
        obj = objects[rng.integers(len(objects))]
        s = rng.uniform(*scale_range)
        h, w = obj.target.shape
        h, w = max(1, int(round(h * s))), max(1, int(round(w * s)))
        if h > height or w > width:
            continue
        patch = cv2.resize(obj.image, (w, h), interpolation=cv2.INTER_LINEAR)
        patch_labels = cv2.resize(obj.target, (w, h), interpolation=cv2.INTER_NEAREST_EXACT)
        if rng.random() < 0.5:
            patch, patch_labels = patch[:, ::-1], patch_labels[:, ::-1]
        y = rng.integers(0, height - h + 1)
        x = rng.integers(0, width - w + 1)
        inside = patch_labels != labels.IGNORE
        image[y:y + h, x:x + w][inside] = patch[inside]
        target[y:y + h, x:x + w][inside] = patch_labels[inside]
        if teacher.ndim == 2:
            teacher[y:y + h, x:x + w][inside] = labels.IGNORE
        else:
            teacher[y:y + h, x:x + w, -1][inside] = 0
