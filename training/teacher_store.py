"""Where the distillation teacher's per-image targets live while a run trains.

The soft distillation keeps the base network's whole class distribution for every training image
(about 14 MB an image at 1024x320 in float16): 114 images are 1.6 GB, but the several hundred
images that make_camera_labels writes from a user's SemanticKITTI sequences are more than a
24 GB machine holds beside the training. On disk, each image's targets are one .npy file,
memory-mapped for each read: a crop reads its image's file from the page cache, and the
training's resident memory no longer grows with the number of images. Nothing stays open between
reads (a map holds a file descriptor, and a few thousand images would pass a 1024-file limit).
"""

import os
import shutil

import numpy as np

MODES = ("auto", "memory", "disk")
# auto: on disk once the targets would take more than this share of the memory available at the
# start (the images, the network, the optimiser and the page cache need the rest).
AUTO_MEMORY_SHARE = 0.25


def available_memory_bytes(meminfo="/proc/meminfo"):
    """MemAvailable of /proc/meminfo in bytes; None where it cannot be read (not Linux)."""
    try:
        with open(meminfo) as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def choose_place(mode, estimate_bytes, available_bytes):
    """'memory' or 'disk' for a store of estimate_bytes; auto keeps memory where the available
    memory is unknown."""
    if mode not in MODES:
        raise ValueError(f"teacher store {mode!r}: one of {', '.join(MODES)}")
    if mode != "auto":
        return mode
    if available_bytes is None:
        return "memory"
    return "disk" if estimate_bytes > AUTO_MEMORY_SHARE * available_bytes else "memory"


class StoredArray:
    """An array in a .npy file, read through a memory map opened for each access: shape, dtype,
    indexing (what a crop needs) and np.asarray."""

    def __init__(self, path, shape, dtype):
        self.path = path
        self.shape = shape
        self.dtype = dtype
        self.ndim = len(shape)

    def __getitem__(self, index):
        return np.array(np.load(self.path, mmap_mode="r")[index])  # a copy: the map closes here

    def __array__(self, dtype=None):
        out = np.load(self.path)
        return out if dtype is None else out.astype(dtype)


class TeacherStore:
    """Keeps one array per training image, in memory or as memory-mapped files in folder.

    The place is decided at the first array kept (its size times count is the estimate), so the
    caller need not know the teacher's channel count. close() removes the folder; the arrays it
    handed out must not be read after it.
    """

    def __init__(self, mode, folder, count, available_bytes=None):
        self.mode = mode
        self.folder = folder
        self.count = count
        self.available_bytes = available_bytes
        self.place = None
        self.bytes_kept = 0
        choose_place(mode, 0, None)  # a bad mode fails here, before the teacher's pass

    def keep(self, index, array):
        """The array to hold for image index: array itself, or a StoredArray of its file."""
        if self.place is None:
            self.place = choose_place(self.mode, array.nbytes * self.count, self.available_bytes)
            if self.place == "disk":
                if os.path.exists(self.folder):
                    shutil.rmtree(self.folder)  # a killed run's leftovers
                os.makedirs(self.folder)
        self.bytes_kept += array.nbytes
        if self.place == "memory":
            return array
        path = os.path.join(self.folder, f"{index:06d}.npy")
        partial = path + ".partial"
        with open(partial, "wb") as f:
            np.save(f, np.ascontiguousarray(array))
        os.replace(partial, path)
        return StoredArray(path, array.shape, array.dtype)

    def describe(self):
        """One phrase for the log: how much is held and where."""
        gb = self.bytes_kept / 1e9
        if self.place == "disk":
            return f"{gb:.1f} GB on disk in {self.folder}, memory-mapped"
        return f"{gb:.1f} GB held in memory"

    def close(self):
        if self.place == "disk" and os.path.isdir(self.folder):
            shutil.rmtree(self.folder, ignore_errors=True)
