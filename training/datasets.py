"""The KITTI camera's training data in ../shared, prepared at the network's input scale:
dense human labels (kitti_semantics), the human lidar labels projected into both cameras
(semantickitti_train: sparse) and, optionally, CamVid. SemanticKITTI 05 and 08 are the
evaluation frames and are refused here."""

import glob
import os
from dataclasses import dataclass, field

import cv2
import numpy as np

import labels
import preprocess

EVALUATION_SEQUENCES = ("05", "08")
# The KITTI raw drives SemanticKITTI 05 and 08 were made from (its odometry sequences' sources).
EVALUATION_RAW_DRIVES = ("2011_09_30_drive_0018", "2011_09_30_drive_0028")
SPARSE_SEQUENCES = ("01", "02", "03", "06", "09")


class DatasetError(RuntimeError):
    pass


def _thumbnail(image):
    """A 64x20 grey thumbnail (area averaging): the same picture re-encoded, resized or cut by a
    few pixels stays within a few grey levels of it; another frame of a drive is 7-17 away on
    average, another scene 38 or more (measured on ../shared)."""
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return cv2.resize(grey, (64, 20), interpolation=cv2.INTER_AREA).astype(np.float32)


class EvaluationFrames:
    """Refuses the evaluation frames under any name: an image from a folder of the raw drives of
    SemanticKITTI 05 / 08, or whose picture is one of the evaluation images in shared (a mean
    grey difference below `threshold` on the thumbnail). Folder names alone let them through
    renamed (make_camera_labels writes any sequence under any number) or as pseudo-label
    images."""

    def __init__(self, shared, threshold=5.0):
        self.threshold = threshold
        self.frames = {}
        for seq in EVALUATION_SEQUENCES:
            for path in sorted(glob.glob(os.path.join(shared, "data", "semantickitti", "sequences",
                                                      seq, "image_2", "*.png"))):
                image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
                if image is not None:
                    self.frames[path] = _thumbnail(image)

    def check(self, path, image):
        real = os.path.realpath(path)
        for drive in EVALUATION_RAW_DRIVES:
            if drive in real:
                raise DatasetError(f"{path}: an image of the raw drive {drive}, which SemanticKITTI "
                                   f"{EVALUATION_SEQUENCES[EVALUATION_RAW_DRIVES.index(drive)]} "
                                   "was made from: the evaluation frames are never trained on")
        if not self.frames:
            return
        thumb = _thumbnail(image)
        nearest, distance = min(((p, float(np.abs(thumb - t).mean())) for p, t in
                                 self.frames.items()), key=lambda pair: pair[1])
        if distance < self.threshold:
            raise DatasetError(f"{path}: the same picture as the evaluation frame {nearest} "
                               f"(mean grey difference {distance:.1f} of 255): SemanticKITTI 05 "
                               "and 08 are never trained on")


_evaluation_frames = None


def refuse_evaluation_frames(shared):
    """From now on every image read for training or validation is checked (EvaluationFrames).
    Returns how many evaluation images it compares with (0: only the drive names)."""
    global _evaluation_frames
    _evaluation_frames = EvaluationFrames(shared)
    return len(_evaluation_frames.frames)


def sequence_id(seq):
    """The sequence a --sparse-sequences / --val-sequence entry names, however it is spelt:
    the last component of the normalised path ("05/", "./05" and "x/../05" are 05) as an integer
    when it is one (5 and "005" are 05 too), else that component."""
    name = os.path.basename(os.path.normpath(str(seq).strip()))
    return int(name) if name.isdigit() else name


def is_evaluation_sequence(seq):
    """Whether seq names SemanticKITTI 05 or 08 (sequence_id), the frames the result is scored
    on."""
    return sequence_id(seq) in {int(s) for s in EVALUATION_SEQUENCES}


@dataclass
class Sample:
    name: str
    kind: str  # "dense", "sparse" or "camvid"
    image: np.ndarray  # H x W x 3 uint8 BGR, the card's colours, at the network's input size
    target: np.ndarray  # H x W uint8 trainIds, 255 where no human label
    teacher: np.ndarray = field(default=None)  # H x W uint8 trainIds of the base network, 255 unsure
    label_weight: float = 1.0  # this image's human-label loss is scaled by it (its source's weight)


def _read_image(path):
    image = cv2.imread(path, cv2.IMREAD_COLOR)
    if image is None:
        raise DatasetError(f"cannot read image {path}")
    if _evaluation_frames is not None:
        _evaluation_frames.check(path, image)
    return image


def _read_label(path, flags):
    label = cv2.imread(path, flags if flags != cv2.IMREAD_GRAYSCALE else cv2.IMREAD_UNCHANGED)
    if label is None:
        raise DatasetError(f"cannot read label image {path}")
    if flags == cv2.IMREAD_GRAYSCALE and (label.ndim != 2 or label.dtype != np.uint8):
        # A colour label (KITTI's semantic_rgb/) read as grey gave luminances, nearly none a
        # labelId: the run trained on almost no labels, exit 0.
        raise DatasetError(f"label image {path} is not one channel of 8-bit labelIds "
                           f"({label.shape[2] if label.ndim == 3 else 1} channels, "
                           f"{label.dtype}): the colour labels (semantic_rgb/) are not read")
    return label


def _check_same_size(image, label, image_path, label_path):
    if image.shape[:2] != label.shape[:2]:
        raise DatasetError(
            f"label image {label_path} is {label.shape[1]}x{label.shape[0]} but its image "
            f"{image_path} is {image.shape[1]}x{image.shape[0]}")


def scatter_sparse(train_ids, width, height):
    """A sparse label image at another size: every labelled pixel lands on its scaled position
    (nearest-neighbour resizing would drop most of the 1-pixel lidar labels)."""
    out = np.full((height, width), labels.IGNORE, np.uint8)
    v, u = np.nonzero(train_ids != labels.IGNORE)
    sx, sy = width / train_ids.shape[1], height / train_ids.shape[0]
    uu = np.clip(((u + 0.5) * sx).astype(int), 0, width - 1)
    vv = np.clip(((v + 0.5) * sy).astype(int), 0, height - 1)
    out[vv, uu] = train_ids[v, u]
    return out


def _prepare(image, width, height, gamma, standardize):
    return preprocess.resize_to_input(preprocess.card_colors(image, gamma, standardize), width,
                                      height)


def _sparse_sample(name, image_path, label_path, dtype, lut, width, height, gamma, standardize):
    """A sparse sample: a one-channel label image of `dtype` (0 where none), mapped through lut
    and scattered to the input size."""
    image = _read_image(image_path)
    label = _read_label(label_path, cv2.IMREAD_UNCHANGED)
    if label.dtype != dtype or label.ndim != 2:
        bits = 8 * np.dtype(dtype).itemsize
        raise DatasetError(f"{label_path}: expected a {bits}-bit one-channel label image")
    _check_same_size(image, label, image_path, label_path)
    return Sample(name, "sparse", _prepare(image, width, height, gamma, standardize),
                  scatter_sparse(lut[label], width, height))


def load_dense(root, width, height, gamma, standardize, limit=None):
    """kitti_semantics/training: image_2/*.jpg|png with semantic/*.png (Cityscapes labelIds)."""
    image_dir, label_dir = os.path.join(root, "image_2"), os.path.join(root, "semantic")
    if not os.path.isdir(image_dir) or not os.path.isdir(label_dir):
        raise DatasetError(f"{root}: expected image_2/ and semantic/ (KITTI semantics layout)")
    lut = labels.label_id_to_train_id_lut()
    samples = []
    for label_path in sorted(glob.glob(os.path.join(label_dir, "*.png")))[:limit]:
        stem = os.path.splitext(os.path.basename(label_path))[0]
        candidates = [os.path.join(image_dir, stem + e) for e in (".png", ".jpg")]
        image_path = next((p for p in candidates if os.path.exists(p)), None)
        if image_path is None:
            raise DatasetError(f"{label_path}: no image {stem}.png|jpg in {image_dir}")
        image = _read_image(image_path)
        label = _read_label(label_path, cv2.IMREAD_GRAYSCALE)
        _check_same_size(image, label, image_path, label_path)
        target = cv2.resize(lut[label], (width, height), interpolation=cv2.INTER_NEAREST_EXACT)
        samples.append(Sample(f"kitti_semantics/{stem}", "dense",
                              _prepare(image, width, height, gamma, standardize), target))
    if not samples:
        raise DatasetError(f"{label_dir}: no label images")
    return samples


# SemanticKITTI's "parking" (the evaluation scores it as road, as a Cityscapes network labels it).
SEMANTICKITTI_PARKING = 44


def load_sparse(root, sequences, width, height, gamma, standardize, limit=None,
                parking_as_road=True):
    """semantickitti_train/sequences/NN: image_{2,3}/*.jpg with labels_{2,3}/*.png (16-bit
    SemanticKITTI classes of the lidar points seen at that pixel, 0 where none).
    parking_as_road=False leaves the parking points unlabelled (Cityscapes' own labels never
    trained its networks on parking: there they are void)."""
    lut = labels.semantickitti_to_train_id_lut()
    if not parking_as_road:
        lut = lut.copy()
        lut[SEMANTICKITTI_PARKING] = labels.IGNORE
    samples = []
    for seq in sequences:
        if is_evaluation_sequence(seq):
            raise DatasetError(f"SemanticKITTI {seq} is an evaluation sequence: never trained on")
        seq_dir = os.path.join(root, "sequences", seq)
        if not os.path.isdir(seq_dir):
            raise DatasetError(f"{seq_dir}: no such sequence folder")
        found = len(samples)
        for cam in ("2", "3"):
            for label_path in sorted(glob.glob(os.path.join(seq_dir, f"labels_{cam}", "*.png"))):
                stem = os.path.splitext(os.path.basename(label_path))[0]
                image_path = os.path.join(seq_dir, f"image_{cam}", stem + ".jpg")
                if not os.path.exists(image_path):
                    image_path = os.path.join(seq_dir, f"image_{cam}", stem + ".png")
                samples.append(_sparse_sample(
                    f"semantickitti_train/{seq}/image_{cam}/{stem}", image_path, label_path,
                    np.uint16, lut, width, height, gamma, standardize))
        if len(samples) == found:
            raise DatasetError(f"{seq_dir}: no label images in labels_2/ or labels_3/ (the "
                               "camera-label layout: image_{2,3}/ with labels_{2,3}/*.png, what "
                               "make_camera_labels writes from a SemanticKITTI sequence)")
    if limit is not None:
        samples = samples[:limit]
    return samples


def load_pseudo(labels_dir, images_dir, width, height, gamma, standardize, limit=None):
    """Pseudo-labels: the fused map's classes at each frame's lidar points as its camera sees
    them (semantic_map_offline --label-images: labels_dir/<stem>.png, 8-bit Cityscapes labelIds,
    0 where none), for the images images_dir/<stem>.png of a drive nobody labelled. Sparse, as
    the projected lidar labels are."""
    if not os.path.isdir(labels_dir):
        raise DatasetError(f"{labels_dir}: no such pseudo-label folder")
    lut = labels.label_id_to_train_id_lut()
    samples = []
    for label_path in sorted(glob.glob(os.path.join(labels_dir, "*.png")))[:limit]:
        stem = os.path.splitext(os.path.basename(label_path))[0]
        image_path = os.path.join(images_dir, stem + ".png")
        if not os.path.exists(image_path):
            raise DatasetError(f"{label_path}: no image {image_path}")
        samples.append(_sparse_sample(f"pseudo/{stem}", image_path, label_path, np.uint8, lut,
                                      width, height, gamma, standardize))
    if not samples:
        raise DatasetError(f"{labels_dir}: no label images")
    return samples


def evenly_spaced(items, limit):
    """`limit` items spread evenly over the list (all of them without a limit), so that a few
    frames of a video dataset come from all of its sequences rather than the first one."""
    if not limit or limit >= len(items):
        return list(items)
    picks = np.linspace(0, len(items) - 1, limit).round().astype(int)
    return [items[i] for i in picks]


def load_camvid(root, width, height, gamma, standardize, limit=None):
    """CamVid (SegNet layout): train/*.png|jpg with trainannot/*.png (11 classes); with a limit,
    frames spread over all of its drives."""
    lut = labels.camvid_to_train_id_lut()
    samples = []
    label_paths = sorted(glob.glob(os.path.join(root, "trainannot", "*.png")))
    if not label_paths:
        raise DatasetError(f"{root}/trainannot: no CamVid label images")
    for label_path in evenly_spaced(label_paths, limit):
        stem = os.path.splitext(os.path.basename(label_path))[0]
        candidates = [os.path.join(root, "train", stem + e) for e in (".jpg", ".png")]
        image_path = next((p for p in candidates if os.path.exists(p)), None)
        if image_path is None:
            raise DatasetError(f"{label_path}: no image for it in {root}/train")
        image = _read_image(image_path)
        label = _read_label(label_path, cv2.IMREAD_GRAYSCALE)
        _check_same_size(image, label, image_path, label_path)
        # CamVid's 4:3 frames at the KITTI input's height; crops take KITTI-wide windows (padded).
        # The teacher labels the whole frame, and the network needs sides in multiples of 32.
        h = height
        w = max(32, int(round(image.shape[1] * h / image.shape[0] / 32.0)) * 32)
        prepared = preprocess.resize_to_input(preprocess.card_colors(image, gamma, standardize),
                                              w, h)
        target = cv2.resize(lut[label], (w, h), interpolation=cv2.INTER_NEAREST_EXACT)
        samples.append(Sample(f"camvid/{stem}", "camvid", prepared, target))
    return samples


def split_validation(samples, every):
    """Every `every`-th dense frame and every sample of the held-out sparse sequence go to
    validation (the caller passes which); returns (train, val)."""
    if every < 1:
        raise DatasetError(f"--dense-val-every {every}: must be 1 or more")
    train, val = [], []
    dense_index = 0
    for s in samples:
        if s.kind == "dense":
            (val if dense_index % every == every - 1 else train).append(s)
            dense_index += 1
        else:
            train.append(s)
    return train, val
