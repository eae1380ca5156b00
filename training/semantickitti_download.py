"""A SemanticKITTI download turned into the camera-label layout the training reads.

The download (dataset/sequences/NN/ with velodyne/, labels/, calib.txt, poses.txt, times.txt, and
the odometry benchmark's colour images image_2/, image_3/) holds human lidar labels for sequences
00-10. make_camera_labels (a C++ tool of this package) projects each kept frame's labels into both
cameras through the mapping's own occlusion test; this module finds the sequences to convert,
runs the tool on each and says what the training should read. 05 and 08 are never converted: they
are the frames the result is scored on.
"""

import os
import shutil
import subprocess

import datasets


class DownloadError(Exception):
    """A download that cannot be converted; the message names the folder or the tool."""


def trainable_sequences(root):
    """The sequences/NN of root that hold labelled scans and the left images (velodyne/, labels/,
    image_2/), without the evaluation sequences; sorted."""
    folder = os.path.join(root, "sequences")
    if not os.path.isdir(folder):
        raise DownloadError(f"{root}: no sequences/ folder (the SemanticKITTI dataset/ folder "
                            "holds sequences/00 .. 21)")
    found = []
    for name in sorted(os.listdir(folder)):
        path = os.path.join(folder, name)
        if datasets.is_evaluation_sequence(name) or not os.path.isdir(path):
            continue
        if all(os.path.isdir(os.path.join(path, d)) for d in ("velodyne", "labels", "image_2")):
            found.append(name)
    if not found:
        raise DownloadError(f"{folder}: no sequence with velodyne/, labels/ and image_2/ besides "
                            f"{' and '.join(datasets.EVALUATION_SEQUENCES)} (the colour images "
                            "are the odometry benchmark's data_odometry_color download)")
    return found


def split_validation(sequences, wanted):
    """(training sequences, validation sequence): wanted when present, else the last one; with a
    single sequence, no validation sequence ('': the dense frames' held-out ones remain)."""
    if len(sequences) < 2:
        return list(sequences), ""
    same = [s for s in sequences
            if wanted and datasets.sequence_id(s) == datasets.sequence_id(wanted)]
    val = same[0] if same else sequences[-1]
    return [s for s in sequences if s != val], val


def find_make_camera_labels(repo_root):
    """The make_camera_labels executable: the workspace's build (ISM_BIN, which scripts/env.sh
    sets from ISM_WS, else .ws of the repository), else one on PATH."""
    bin_dir = os.environ.get("ISM_BIN") or os.path.join(repo_root, ".ws", "devel", "lib",
                                                         "inekf_semantic_mapping")
    built = os.path.join(bin_dir, "make_camera_labels")
    if os.access(built, os.X_OK):
        return built
    on_path = shutil.which("make_camera_labels")
    if on_path:
        return on_path
    raise DownloadError(f"make_camera_labels not found ({built} nor on PATH): scripts/build.sh "
                        "builds it")


def convert(root, sequences, out_root, every, tool, log):
    """Runs tool on each sequence into out_root/sequences/NN (every every-th frame); a failure
    raises DownloadError with the tool's last output lines."""
    for seq in sequences:
        command = [tool, "--sequence", os.path.join(root, "sequences", seq), "--output",
                   os.path.join(out_root, "sequences", seq), "--every", str(every)]
        log(f"camera labels of sequence {seq}: {' '.join(command)}")
        run = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if run.returncode != 0:
            tail = "\n".join(run.stdout.strip().splitlines()[-5:])
            raise DownloadError(f"make_camera_labels failed on sequence {seq} "
                                f"(exit {run.returncode}):\n{tail}")
        lines = run.stdout.strip().splitlines()
        if lines:
            log(lines[-1])
