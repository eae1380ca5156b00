"""ONNX export of a segmentation module at a fixed input size, and a parity check against OpenCV's DNN module.

The exported graph takes a 1x3xHxW RGB blob scaled to [0, 1] (what ``cv2.dnn.blobFromImage(img_bgr, 1/255, (W, H),
swapRB=True)`` gives) when the module is a :class:`espnetv2.NormalizedSegmenter`, and returns 1xCxHxW logits.
Opset 11 is the one OpenCV 4.6's importer handles best (Resize with align_corners, Slice, ...).
"""

from __future__ import annotations

import time
import warnings
from typing import Dict, Iterable, List, Optional

import numpy as np
import torch
import torch.nn as nn


def export_onnx(model: nn.Module, path: str, width: int, height: int, opset: int = 11,
                input_name: str = "input", output_name: str = "logits") -> str:
    """Export ``model`` (eval mode, batch 1, fixed ``height`` x ``width``) to ``path``; returns ``path``.
    All shapes are baked in as constants (OpenCV 4.6 wants static shapes); constant folding is on so weight
    slices become plain initializers and BatchNorm is folded where the exporter can."""
    if width % 32 or height % 32:
        warnings.warn(f"export size {width}x{height} is not a multiple of 32")
    was_training = model.training
    model.eval()
    try:
        dummy = torch.rand(1, 3, height, width, device=next(model.parameters()).device)
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")   # TracerWarnings about int(shape): intended, sizes are fixed
            torch.onnx.export(model, dummy, path, opset_version=opset, input_names=[input_name],
                              output_names=[output_name], do_constant_folding=True,
                              training=torch.onnx.TrainingMode.EVAL)
    finally:
        model.train(was_training)
    return path


def preprocess_for_torch(img_bgr: np.ndarray, width: int, height: int) -> torch.Tensor:
    """The exact tensor OpenCV will see: blobFromImage(img_bgr, 1/255, (width, height), swapRB=True)."""
    import cv2
    blob = cv2.dnn.blobFromImage(img_bgr, 1.0 / 255.0, (width, height), swapRB=True, crop=False)
    return torch.from_numpy(np.ascontiguousarray(blob, dtype=np.float32))


def load_opencv_net(onnx_path: str, threads: Optional[int] = None):
    import cv2
    if threads is not None:
        cv2.setNumThreads(threads)
    net = cv2.dnn.readNetFromONNX(onnx_path)
    net.setPreferableBackend(cv2.dnn.DNN_BACKEND_OPENCV)
    net.setPreferableTarget(cv2.dnn.DNN_TARGET_CPU)
    return net


def check_onnx_against_torch(model: nn.Module, onnx_path: str, images: Iterable, width: Optional[int] = None,
                             height: Optional[int] = None, threads: Optional[int] = 2) -> Dict[str, float]:
    """Run the ONNX file with cv2.dnn (DNN_BACKEND_OPENCV, CPU) and ``model`` (PyTorch, eval) on the same blobs.

    ``images``: BGR uint8 arrays (as cv2.imread gives) or paths; each is turned into
    blobFromImage(img, 1/255, (width, height), swapRB=True) and fed unchanged to both.  ``width``/``height``
    default to the ONNX input size.  Returns max_abs_diff (over all logits), mean_abs_diff, argmax_agreement
    (fraction of pixels with the same arg-max over all images), min_image_agreement, n_images, pixels.
    Raises ValueError when no pixel was compared (no image given): an empty check proves nothing.
    """
    import cv2
    if width is None or height is None:
        width, height = onnx_input_size(onnx_path)
    net = load_opencv_net(onnx_path, threads)
    was_training = model.training
    model.eval()
    device = next(model.parameters()).device
    max_abs, sum_abs, n_vals, agree, n_pix, n_img = 0.0, 0.0, 0, 0, 0, 0
    min_agree = 1.0
    try:
        for img in images:
            if isinstance(img, str):
                path = img
                img = cv2.imread(path, cv2.IMREAD_COLOR)
                if img is None:
                    raise FileNotFoundError(path)
            blob = cv2.dnn.blobFromImage(img, 1.0 / 255.0, (width, height), swapRB=True, crop=False)
            net.setInput(blob)
            out_cv = net.forward()
            with torch.no_grad():
                out_t = model(torch.from_numpy(blob).to(device)).float().cpu().numpy()
            if out_cv.shape != out_t.shape:
                raise RuntimeError(f"shape mismatch: OpenCV {out_cv.shape} vs torch {out_t.shape}")
            d = np.abs(out_cv - out_t)
            max_abs = max(max_abs, float(d.max()))
            sum_abs += float(d.sum())
            n_vals += d.size
            same = out_cv.argmax(1) == out_t.argmax(1)
            agree += int(same.sum())
            n_pix += same.size
            min_agree = min(min_agree, float(same.mean()))
            n_img += 1
    finally:
        model.train(was_training)
    if n_pix == 0:
        raise ValueError(f"no image to compare {onnx_path} with PyTorch on ({n_img} images, "
                         "0 pixels): the parity check needs at least one")
    return {
        "max_abs_diff": max_abs,
        "mean_abs_diff": sum_abs / max(n_vals, 1),
        "argmax_agreement": agree / max(n_pix, 1),
        "min_image_agreement": min_agree,
        "n_images": n_img,
        "pixels": n_pix,
    }


def onnx_input_size(onnx_path: str):
    """(width, height) of the first input of an ONNX file (needs the onnx package)."""
    import onnx
    m = onnx.load(onnx_path)
    dims = [d.dim_value for d in m.graph.input[0].type.tensor_type.shape.dim]
    return int(dims[3]), int(dims[2])


def time_opencv_forward(onnx_path: str, width: int, height: int, threads: int = 2, repeats: int = 5,
                        warmup: int = 1) -> Dict[str, float]:
    """Median / min wall time (ms) of cv2.dnn forward at the ONNX's fixed size with ``threads`` threads."""
    net = load_opencv_net(onnx_path, threads)
    blob = np.random.RandomState(0).rand(1, 3, height, width).astype(np.float32)
    times: List[float] = []
    for i in range(warmup + repeats):
        net.setInput(blob)
        t0 = time.perf_counter()
        net.forward()
        if i >= warmup:
            times.append((time.perf_counter() - t0) * 1e3)
    return {"median_ms": float(np.median(times)), "min_ms": float(np.min(times)), "repeats": repeats}


def onnx_op_histogram(onnx_path: str) -> Dict[str, int]:
    """Node type counts of an ONNX graph (for a quick look at what OpenCV has to import)."""
    import onnx
    m = onnx.load(onnx_path)
    hist: Dict[str, int] = {}
    for n in m.graph.node:
        hist[n.op_type] = hist.get(n.op_type, 0) + 1
    return dict(sorted(hist.items()))
