"""Scores of a labelling against the human labels, over the 19 Cityscapes trainIds."""

import numpy as np

import labels


class Scorer:
    """Confusion over the 19 trainIds: pixel accuracy and mIoU (classes present in truth)."""

    def __init__(self):
        self.confusion = np.zeros((labels.NUM_TRAIN_IDS, labels.NUM_TRAIN_IDS), np.int64)

    def add(self, truth, predicted):
        keep = truth != labels.IGNORE
        t = truth[keep].astype(np.int64)
        p = np.minimum(predicted[keep].astype(np.int64), labels.NUM_TRAIN_IDS - 1)
        n = labels.NUM_TRAIN_IDS
        self.confusion += np.bincount(t * n + p, minlength=n * n).reshape(n, n)

    def accuracy(self):
        total = self.confusion.sum()
        return float(np.trace(self.confusion) / total) if total else float("nan")

    def miou(self):
        tp = np.diag(self.confusion).astype(float)
        union = self.confusion.sum(0) + self.confusion.sum(1) - tp
        present = self.confusion.sum(1) > 0
        return float(np.mean(tp[present] / union[present])) if present.any() else float("nan")
