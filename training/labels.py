"""Label tables, read from the C++ headers so that training and the C++ evaluation share one
source: Cityscapes labelId -> trainId (perception/cityscapes.h) and SemanticKITTI class ->
Cityscapes labelId (perception/semantickitti_to_cityscapes.h)."""

import os
import re

import numpy as np

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
HEADER_DIR = os.path.join(REPO_ROOT, "include", "inekf_semantic_mapping", "perception")
IGNORE = 255
NUM_TRAIN_IDS = 19
# The networks' output channels: trainIds 0..18, then "background" (Cityscapes' void).
NUM_CLASSES = NUM_TRAIN_IDS + 1
BACKGROUND_CHANNEL = NUM_TRAIN_IDS


class LabelTableError(RuntimeError):
    pass


def _read(name):
    path = os.path.join(HEADER_DIR, name)
    with open(path, encoding="utf-8") as f:
        return path, f.read()


def cityscapes_table():
    """[(label_id, name, train_id)] from cityscapes.h's kLabels."""
    path, text = _read("cityscapes.h")
    rows = re.findall(r'\{(\d+), "([^"]+)", (\d+), \d+, \d+, \d+\}', text)
    if len(rows) != 34:
        raise LabelTableError(f"{path}: expected 34 kLabels rows, parsed {len(rows)}")
    return [(int(a), n, int(t)) for a, n, t in rows]


def cityscapes_constants():
    """kName -> labelId from cityscapes.h's LabelId enum."""
    path, text = _read("cityscapes.h")
    constants = {k: int(v) for k, v in re.findall(r"\b(k[A-Z]\w*) = (\d+),", text)}
    if "kRoad" not in constants:
        raise LabelTableError(f"{path}: no LabelId enum parsed")
    return constants


def label_id_to_train_id_lut():
    """256-entry uint8 LUT: Cityscapes labelId -> trainId (255 ignored)."""
    lut = np.full(256, IGNORE, np.uint8)
    for label_id, _, train_id in cityscapes_table():
        lut[label_id] = train_id
    return lut


def train_id_to_label_id():
    """Output channel -> Cityscapes labelId, in the network's channel order (background -> 0)."""
    ids = [0] * NUM_CLASSES
    for label_id, _, train_id in cityscapes_table():
        if train_id != IGNORE:
            ids[train_id] = label_id
    return ids


def train_id_names():
    names = [""] * NUM_TRAIN_IDS
    for _, name, train_id in cityscapes_table():
        if train_id != IGNORE:
            names[train_id] = name
    return names


def semantickitti_to_train_id_lut():
    """65536-entry uint8 LUT: SemanticKITTI class -> Cityscapes trainId (255 not scored), by the
    switch of semantickitti_to_cityscapes.h (the table evaluate_semantics scores with)."""
    path, text = _read("semantickitti_to_cityscapes.h")
    body = text.split("switch (semantic_kitti_class) {", 1)
    if len(body) != 2:
        raise LabelTableError(f"{path}: no switch on semantic_kitti_class")
    constants = cityscapes_constants()
    to_train = label_id_to_train_id_lut()
    lut = np.full(65536, IGNORE, np.uint8)
    pending = []
    mapped = 0
    for line in body[1].split("default:", 1)[0].splitlines():
        case = re.match(r"\s*case (\d+):", line)
        if case:
            pending.append(int(case.group(1)))
        ret = re.search(r"return (?:cs::(k\w+)|(\d+));", line)
        if ret:
            label_id = constants[ret.group(1)] if ret.group(1) else int(ret.group(2))
            for c in pending:
                lut[c] = to_train[label_id]
                mapped += 1
            pending = []
    if mapped < 20 or pending:
        raise LabelTableError(f"{path}: parsed {mapped} mapped classes ({pending} without return)")
    return lut


# CamVid (SegNet version) class index -> Cityscapes trainId; sign-symbol and bicyclist mix two
# Cityscapes classes each (sign / light, rider / bicycle) and are ignored.
CAMVID_TO_TRAIN_ID = {0: 10, 1: 2, 2: 5, 3: 0, 4: 1, 5: 8, 6: IGNORE, 7: 4, 8: 13, 9: 11,
                      10: IGNORE, 11: IGNORE}


def camvid_to_train_id_lut():
    lut = np.full(256, IGNORE, np.uint8)
    for k, v in CAMVID_TO_TRAIN_ID.items():
        lut[k] = v
    return lut
