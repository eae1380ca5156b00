#!/usr/bin/python3
"""Tests of the camera adaptation (training/): the label tables it shares with the C++
evaluation, the sparse-label and lidar-zone helpers, the C++ Segmenter's preprocessing in numpy,
and the whole pipeline on a tiny budget (a few steps on a few images of ../shared): its ONNX
export must load in the C++ Segmenter (segment_image) and label the held-out images as PyTorch
does. Runs standalone or as the test node of test/ros/adapt_segmentation.test (rostest records
the result for catkin)."""

import json
import shutil
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
sys.path.insert(0, os.path.join(REPO_ROOT, "training"))
sys.path.insert(0, os.path.join(REPO_ROOT, "test", "ros"))
import base_networks  # noqa: E402
import datasets  # noqa: E402
import labels  # noqa: E402
import preprocess  # noqa: E402

try:
    import torch  # noqa: F401

    HAVE_TORCH = True
except ImportError:
    HAVE_TORCH = False


def shared_dir():
    return os.environ.get("ISM_SHARED_DIR") or os.path.join(REPO_ROOT, "..", "shared")


def skip_loudly(test, what):
    print(f"\n*** SKIPPED: {what}\n", file=sys.stderr, flush=True)
    test.skipTest(what)


def require_torch(test):
    """Skips the test, loudly, where PyTorch (needed only for training) is not installed."""
    if not HAVE_TORCH:
        skip_loudly(test, "PyTorch not installed (scripts/install_deps.sh)")


class LabelTables(unittest.TestCase):
    def test_semantickitti_classes_map_as_the_cpp_evaluation_scores_them(self):
        lut = labels.semantickitti_to_train_id_lut()
        names = labels.train_id_names()
        expect = {10: "car", 252: "car", 44: "road", 60: "road", 40: "road", 48: "sidewalk",
                  71: "vegetation", 72: "terrain", 80: "pole", 81: "traffic sign",
                  253: "rider", 18: "truck", 50: "building", 51: "fence", 30: "person"}
        for sk, name in expect.items():
            self.assertEqual(names[lut[sk]], name, sk)
        for ignored in (0, 1, 20, 49, 52, 99, 259):
            self.assertEqual(lut[ignored], labels.IGNORE, ignored)

    def test_channels_are_train_ids_then_void(self):
        ids = labels.train_id_to_label_id()
        self.assertEqual(len(ids), labels.NUM_CLASSES)
        self.assertEqual(ids[0], 7)  # road
        self.assertEqual(ids[13], 26)  # car
        self.assertEqual(ids[labels.BACKGROUND_CHANNEL], 0)
        lut = labels.label_id_to_train_id_lut()
        for channel, label_id in enumerate(ids[:-1]):
            self.assertEqual(lut[label_id], channel)


class SparseLabels(unittest.TestCase):
    def test_scatter_keeps_every_point_when_upscaling_and_puts_it_in_place(self):
        sparse = np.full((10, 20), labels.IGNORE, np.uint8)
        sparse[2, 3], sparse[7, 15], sparse[9, 19] = 0, 13, 8
        up = datasets.scatter_sparse(sparse, 40, 20)
        self.assertEqual(int((up != labels.IGNORE).sum()), 3)
        self.assertEqual(up[5, 7], 0)  # (3.5 * 2, 2.5 * 2) -> column 7, row 5
        self.assertEqual(up[15, 31], 13)
        self.assertEqual(up[19, 39], 8)

    def test_lidar_zone_starts_at_the_top_beam_of_nearby_columns(self):
        import adapt_segmentation as adapt

        target = np.full((100, 200), labels.IGNORE, np.uint8)
        target[40, ::4] = 0  # the top beam at row 40, a point every 4 columns
        target[70, :] = 0
        zone = adapt.lidar_zone_mask(target, margin_px=5, column_window=9)
        self.assertTrue(zone[35:, :].all())  # from 5 rows above the beam down
        self.assertFalse(zone[:35, :].any())  # the sky above it is the teacher's


class PseudoLabels(unittest.TestCase):
    """The map's label images (semantic_map_offline --label-images) as sparse training labels."""

    def test_label_ids_become_train_ids_at_their_scaled_pixels(self):
        import cv2

        with tempfile.TemporaryDirectory() as tmp:
            os.makedirs(os.path.join(tmp, "labels"))
            os.makedirs(os.path.join(tmp, "images"))
            label = np.zeros((40, 80), np.uint8)  # labelId 0: none
            label[30, 10], label[35, 60] = 7, 26  # road, car
            cv2.imwrite(os.path.join(tmp, "labels", "0000000003.png"), label)
            cv2.imwrite(os.path.join(tmp, "images", "0000000003.png"),
                        np.full((40, 80, 3), 120, np.uint8))
            [sample] = datasets.load_pseudo(os.path.join(tmp, "labels"),
                                            os.path.join(tmp, "images"), 160, 80, 0.7, True)
            lut = labels.label_id_to_train_id_lut()
            self.assertEqual(sample.kind, "sparse")
            self.assertEqual(sample.target.shape, (80, 160))
            self.assertEqual(int((sample.target != labels.IGNORE).sum()), 2)
            self.assertEqual(sample.target[61, 21], lut[7])
            self.assertEqual(sample.target[71, 121], lut[26])

    def test_a_label_without_its_image_names_both(self):
        import cv2

        with tempfile.TemporaryDirectory() as tmp:
            os.makedirs(os.path.join(tmp, "labels"))
            cv2.imwrite(os.path.join(tmp, "labels", "0000000001.png"), np.zeros((4, 4), np.uint8))
            with self.assertRaisesRegex(datasets.DatasetError, "0000000001.png.*no image"):
                datasets.load_pseudo(os.path.join(tmp, "labels"), os.path.join(tmp, "images"),
                                     32, 32, 0.7, True)


class EvaluationFramesRefused(unittest.TestCase):
    """SemanticKITTI 05 / 08 are never trained on, under any name: by their raw drives' folder
    names and by the picture itself (they were refused by their sequence folder's name only, so a
    renamed copy or pseudo-label images of their drive were trained on)."""

    def tearDown(self):
        datasets._evaluation_frames = None  # the other tests read without the check

    def pseudo_pair(self, root, image):
        import cv2

        os.makedirs(os.path.join(root, "labels"))
        os.makedirs(os.path.join(root, "images"), exist_ok=True)
        label = np.zeros(image.shape[:2], np.uint8)
        label[-10, 10] = 7
        cv2.imwrite(os.path.join(root, "labels", "0000000003.png"), label)
        cv2.imwrite(os.path.join(root, "images", "0000000003.png"), image)
        return os.path.join(root, "labels"), os.path.join(root, "images")

    def test_a_re_encoded_evaluation_frame_is_refused_and_a_training_frame_is_not(self):
        import cv2

        frame = os.path.join(shared_dir(), "data", "semantickitti", "sequences", "05", "image_2",
                             "000000.png")
        dense = os.path.join(shared_dir(), "data", "kitti_semantics", "training", "image_2",
                             "000005_10.jpg")
        if not (os.path.exists(frame) and os.path.exists(dense)):
            skip_loudly(self, f"{frame} or {dense} not there")
        self.assertEqual(datasets.refuse_evaluation_frames(shared_dir()), 20)
        _, jpeg = cv2.imencode(".jpg", cv2.imread(frame), [cv2.IMWRITE_JPEG_QUALITY, 85])
        copy = cv2.resize(cv2.imdecode(jpeg, cv2.IMREAD_COLOR), (1242, 375))
        with tempfile.TemporaryDirectory() as tmp:
            labels_dir, images_dir = self.pseudo_pair(os.path.join(tmp, "copy"), copy)
            with self.assertRaisesRegex(datasets.DatasetError,
                                        r"0000000003\.png: the same picture as the evaluation "
                                        r"frame .*05/image_2/000000\.png"):
                datasets.load_pseudo(labels_dir, images_dir, 160, 64, 0.7, True)
            labels_dir, images_dir = self.pseudo_pair(os.path.join(tmp, "other"),
                                                      cv2.imread(dense))
            self.assertEqual(len(datasets.load_pseudo(labels_dir, images_dir, 160, 64, 0.7, True)),
                             1)

    def test_images_of_the_evaluation_drives_are_refused_by_their_folder(self):
        with tempfile.TemporaryDirectory() as tmp:
            datasets.refuse_evaluation_frames(tmp)  # no evaluation images there: names only
            drive = os.path.join(tmp, "2011_09_30", "2011_09_30_drive_0028_sync", "image_02")
            labels_dir, images_dir = self.pseudo_pair(drive, np.full((40, 80, 3), 90, np.uint8))
            with self.assertRaisesRegex(datasets.DatasetError,
                                        "raw drive 2011_09_30_drive_0028, which SemanticKITTI 08"):
                datasets.load_pseudo(labels_dir, images_dir, 160, 64, 0.7, True)

    def test_an_output_inside_shared_is_refused_before_anything_is_written(self):
        with tempfile.TemporaryDirectory() as tmp:
            result = subprocess.run(
                ["/usr/bin/python3", os.path.join(REPO_ROOT, "training", "adapt_segmentation.py"),
                 "--shared", tmp, "--output", os.path.join(tmp, "models", "x")],
                capture_output=True, text=True)
            self.assertNotEqual(result.returncode, 0)
            self.assertIn(f"--output {tmp}/models/x: inside --shared {tmp}", result.stderr)
            self.assertEqual(os.listdir(tmp), [])


class SparseLidarLabels(unittest.TestCase):
    """The projected SemanticKITTI lidar labels (semantickitti_train) as sparse training labels."""

    def test_parking_is_road_or_left_unlabelled_as_asked(self):
        import cv2

        with tempfile.TemporaryDirectory() as tmp:
            seq = os.path.join(tmp, "sequences", "01")
            for sub in ("image_2", "labels_2"):
                os.makedirs(os.path.join(seq, sub))
            label = np.zeros((40, 80), np.uint16)  # 0: no lidar point
            label[30, 10], label[35, 60], label[20, 40] = 44, 40, 48  # parking, road, sidewalk
            cv2.imwrite(os.path.join(seq, "labels_2", "000000.png"), label)
            cv2.imwrite(os.path.join(seq, "image_2", "000000.jpg"),
                        np.full((40, 80, 3), 120, np.uint8))
            road, sidewalk = labels.semantickitti_to_train_id_lut()[[40, 48]]
            [as_road] = datasets.load_sparse(tmp, ["01"], 80, 40, 0.7, True)
            [left_out] = datasets.load_sparse(tmp, ["01"], 80, 40, 0.7, True,
                                              parking_as_road=False)
            self.assertEqual(as_road.target[30, 10], road)
            self.assertEqual(left_out.target[30, 10], labels.IGNORE)
            for sample in (as_road, left_out):
                self.assertEqual(sample.target[35, 60], road)
                self.assertEqual(sample.target[20, 40], sidewalk)
            self.assertEqual(int((left_out.target != labels.IGNORE).sum()), 2)


class CamVidSubset(unittest.TestCase):
    def test_a_limited_subset_spans_the_list_without_repeats(self):
        frames = [f"{seq}_{i:03d}" for seq in ("0001TP", "0006R0", "0016E5", "Seq05VD")
                  for i in range(90)]
        picked = datasets.evenly_spaced(frames, 8)
        self.assertEqual(len(picked), 8)
        self.assertEqual(len(set(picked)), 8)
        self.assertEqual(picked[0], frames[0])
        self.assertEqual(picked[-1], frames[-1])
        self.assertEqual({p.split("_")[0] for p in picked},
                         {"0001TP", "0006R0", "0016E5", "Seq05VD"})

    def test_frames_come_at_the_input_height_and_a_width_the_network_takes(self):
        import cv2
        with tempfile.TemporaryDirectory() as root:
            os.makedirs(os.path.join(root, "train"))
            os.makedirs(os.path.join(root, "trainannot"))
            image = np.full((720, 960, 3), 90, np.uint8)
            label = np.full((720, 960), 3, np.uint8)  # CamVid 3: road
            cv2.imwrite(os.path.join(root, "train", "0001TP_006690.png"), image)
            cv2.imwrite(os.path.join(root, "trainannot", "0001TP_006690.png"), label)
            samples = datasets.load_camvid(root, 1024, 320, 0.7, True, 1)
        self.assertEqual(len(samples), 1)
        h, w = samples[0].image.shape[:2]
        self.assertEqual(h, 320)
        self.assertEqual(w % 32, 0)  # 427 would not pass the network's downsampling
        self.assertLess(abs(w - 960 * 320 / 720), 32)
        self.assertEqual(samples[0].target.shape, (h, w))
        self.assertTrue((samples[0].target == labels.camvid_to_train_id_lut()[3]).all())

    def test_no_limit_or_a_large_one_keeps_every_frame_in_order(self):
        frames = list(range(5))
        self.assertEqual(datasets.evenly_spaced(frames, 0), frames)
        self.assertEqual(datasets.evenly_spaced(frames, 9), frames)


class Distillation(unittest.TestCase):
    def test_soft_loss_is_zero_for_the_teacher_and_ignores_pixels_outside_the_zone(self):
        require_torch(self)
        import torch
        import torch.nn.functional as F
        import adapt_segmentation as adapt

        torch.manual_seed(0)
        logits = torch.randn(2, 5, 4, 6)
        zone = torch.zeros(2, 1, 4, 6)
        zone[:, :, :2] = 1
        teacher = torch.cat([logits.clone(), zone], dim=1)
        self.assertAlmostEqual(adapt.soft_distillation_loss(logits, teacher, 2.0, F).item(), 0.0,
                               places=5)
        other = logits.clone()
        other[:, :, 2:] = torch.randn(2, 5, 2, 6)  # outside the zone: no effect
        self.assertAlmostEqual(adapt.soft_distillation_loss(other, teacher, 2.0, F).item(), 0.0,
                               places=5)
        other[:, :, :2] = torch.randn(2, 5, 2, 6)  # inside: a positive KL
        self.assertGreater(adapt.soft_distillation_loss(other, teacher, 2.0, F).item(), 0.01)

    def test_frozen_batch_norm_keeps_its_statistics_while_training(self):
        require_torch(self)
        import torch
        import adapt_segmentation as adapt

        model = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 1), torch.nn.BatchNorm2d(4))
        before = model[1].running_mean.clone()
        model.train()
        adapt.freeze_batchnorm_statistics(model, torch)
        model(torch.randn(2, 3, 8, 8) + 5.0)
        self.assertTrue(torch.equal(model[1].running_mean, before))
        model.train()  # without the freeze they move
        model(torch.randn(2, 3, 8, 8) + 5.0)
        self.assertFalse(torch.equal(model[1].running_mean, before))


class LabelLoss(unittest.TestCase):
    def test_each_image_weighs_its_weight_however_many_labels_it_has(self):
        require_torch(self)
        import torch
        import adapt_segmentation as adapt

        ce = torch.zeros(2, 4, 5)
        target = torch.full((2, 4, 5), labels.IGNORE, dtype=torch.int64)
        target[0] = 0  # dense: 20 labels, loss 1 each
        ce[0] = 1.0
        target[1, 0, :2] = 0  # sparse: 2 labels, loss 3 each
        ce[1, 0, :2] = 3.0
        ce[1, 2:] = 50.0  # unlabelled pixels count for nothing
        one = torch.ones(2)
        self.assertAlmostEqual(adapt.per_image_label_loss(ce, target, one).item(), 2.0, places=6)
        half = torch.tensor([1.0, 0.5])
        self.assertAlmostEqual(adapt.per_image_label_loss(ce, target, half).item(), 1.25,
                               places=6)
        none = torch.tensor([1.0, 0.0])
        self.assertAlmostEqual(adapt.per_image_label_loss(ce, target, none).item(), 0.5, places=6)
        target[:] = labels.IGNORE  # no label at all: zero, not NaN
        self.assertEqual(adapt.per_image_label_loss(ce, target, one).item(), 0.0)

    def test_a_negative_sparse_weight_is_refused_naming_the_option(self):
        import adapt_segmentation as adapt

        with self.assertRaises(SystemExit) as e:
            adapt.main(["--shared", "/nonexistent", "--sparse-weight", "-1"])
        self.assertIn("--sparse-weight", str(e.exception))


class RareClassSampling(unittest.TestCase):
    @staticmethod
    def sample(classes):
        target = np.full((10, 20), labels.IGNORE, np.uint8)
        for i, c in enumerate(classes):
            target[:, i * 5:(i + 1) * 5] = c  # 50 pixels each
        return datasets.Sample("s", "dense", np.zeros((10, 20, 3), np.uint8), target)

    def test_an_image_with_a_rare_class_is_drawn_more_often_and_common_ones_once(self):
        import adapt_segmentation as adapt

        road, car, person = 0, 13, 11
        samples = [self.sample([road, car]) for _ in range(9)] + [self.sample([road, person])]
        factors = adapt.repeat_factors(samples, 0.4)
        self.assertTrue(np.all(factors[:9] == 1.0))  # road and car are in every other image
        self.assertAlmostEqual(factors[9], np.sqrt(0.4 / 0.1), places=6)  # person: 1 in 10
        self.assertTrue(np.all(adapt.repeat_factors(samples, 0) == 1.0))

        rng = np.random.default_rng(3)
        draws = [adapt.epoch_order(factors, rng) for _ in range(400)]
        per_epoch = np.mean([d.count(9) for d in draws])
        self.assertAlmostEqual(per_epoch, factors[9], delta=0.08)  # stochastic rounding
        self.assertTrue(all(d.count(0) == 1 for d in draws))

    def test_a_class_below_the_pixel_minimum_does_not_raise_the_factor(self):
        import adapt_segmentation as adapt

        few = self.sample([0])
        few.target[0, 10:13] = 11  # 3 person pixels: not counted as present
        samples = [self.sample([0]) for _ in range(9)] + [few]
        self.assertTrue(np.all(adapt.repeat_factors(samples, 0.5) == 1.0))

    def test_distillation_weights_are_one_in_the_zone_and_the_given_weight_at_labels(self):
        import adapt_segmentation as adapt

        s = self.sample([0, 13])  # columns 0-9 labelled, 10-19 not
        w = adapt.distillation_weights(s, False, 0.3)
        self.assertTrue(np.allclose(w[:, :10], 0.3))
        self.assertTrue(np.all(w[:, 10:] == 1.0))
        self.assertTrue(np.all(adapt.distillation_weights(s, False, 0.0)[:, :10] == 0.0))


class Teacher(unittest.TestCase):
    """Who teaches by distillation: the base network unless another is named."""

    @staticmethod
    def args(teacher="", teacher_init=""):
        import argparse

        return argparse.Namespace(teacher=teacher, teacher_init=teacher_init)

    def test_without_a_teacher_the_base_network_itself_teaches(self):
        import adapt_segmentation as adapt
        import base_networks

        base = base_networks.get("espnetv2_s1")
        model = object()
        teacher, name = adapt.build_teacher(self.args(), base, model, shared_dir(), None)
        self.assertIs(teacher, model)
        self.assertIn("espnetv2_s1", name)

    def test_a_named_teacher_is_its_own_network_and_wrong_weights_name_the_file(self):
        require_torch(self)
        shared = shared_dir()
        import adapt_segmentation as adapt
        import base_networks

        for name in ("espnetv2_s1", "espnetv2_s2"):
            if not os.path.exists(os.path.join(shared, base_networks.get(name).weights)):
                skip_loudly(self, f"shared weights of {name} not found")
        base = base_networks.get("espnetv2_s1")
        student = base.build(os.path.join(shared, base.weights))
        teacher, name = adapt.build_teacher(self.args("espnetv2_s2"), base, student, shared, torch)
        self.assertIsNot(teacher, student)
        self.assertFalse(teacher.training)
        count = lambda m: sum(p.numel() for p in m.parameters())  # noqa: E731
        self.assertGreater(count(teacher), 1.5 * count(student))  # s=2.0 against s=1.0
        self.assertIn("espnetv2_s2", name)
        # The student's weights are not the teacher's: refused, naming the file.
        path = os.path.join(tempfile.mkdtemp(prefix="ism_teacher_"), "student.pt")
        torch.save(student.state_dict(), path)
        with self.assertRaises(SystemExit) as caught:
            adapt.build_teacher(self.args("espnetv2_s2", path), base, student, shared, torch)
        self.assertIn(path, str(caught.exception))
        self.assertIn("espnetv2_s2", str(caught.exception))
        with self.assertRaises(SystemExit) as caught:
            adapt.build_teacher(self.args("espnetv2_s2", path + ".missing"), base, student, shared,
                                torch)
        self.assertIn("no such file", str(caught.exception))


class TeacherStore(unittest.TestCase):
    """The teacher's distributions in memory or memory-mapped from disk: the same numbers either
    way, the folder gone afterwards, and auto going to disk only when memory would run short."""

    def test_auto_goes_to_disk_past_a_quarter_of_the_available_memory(self):
        import teacher_store

        gb = 1 << 30
        self.assertEqual(teacher_store.choose_place("auto", 2 * gb, 20 * gb), "memory")
        self.assertEqual(teacher_store.choose_place("auto", 6 * gb, 20 * gb), "disk")
        self.assertEqual(teacher_store.choose_place("auto", 600 * gb, None), "memory")
        self.assertEqual(teacher_store.choose_place("disk", 1, 20 * gb), "disk")
        self.assertEqual(teacher_store.choose_place("memory", 600 * gb, 20 * gb), "memory")
        with self.assertRaises(ValueError):
            teacher_store.choose_place("ram", 1, 1)

    def test_available_memory_is_read_from_meminfo(self):
        import teacher_store

        folder = tempfile.mkdtemp(prefix="ism_meminfo_")
        path = os.path.join(folder, "meminfo")
        with open(path, "w") as f:
            f.write("MemTotal:       24000000 kB\nMemFree:  100 kB\nMemAvailable:   20000000 kB\n")
        self.assertEqual(teacher_store.available_memory_bytes(path), 20000000 * 1024)
        self.assertIsNone(teacher_store.available_memory_bytes(path + ".missing"))

    def test_disk_keeps_the_same_numbers_holds_no_file_open_and_removes_its_folder(self):
        import teacher_store

        folder = os.path.join(tempfile.mkdtemp(prefix="ism_store_"), "teacher_cache")
        os.makedirs(folder)
        with open(os.path.join(folder, "000007.npy.partial"), "w") as f:
            f.write("a killed run's leftover")
        count = 40
        store = teacher_store.TeacherStore("disk", folder, count)
        rng = np.random.default_rng(0)
        arrays = [rng.normal(size=(4, 6, 3)).astype(np.float16) for _ in range(count)]
        open_before = len(os.listdir("/proc/self/fd"))
        kept = [store.keep(i, a) for i, a in enumerate(arrays)]
        crops = [k[1:3, 2:5] for k in kept]
        # Thousands of images would pass a 1024-file limit if each kept its map open.
        self.assertEqual(len(os.listdir("/proc/self/fd")), open_before)
        self.assertEqual(len(os.listdir(folder)), count)
        for a, k, crop in zip(arrays, kept, crops):
            self.assertIsInstance(k, teacher_store.StoredArray)
            self.assertEqual((k.shape, k.dtype, k.ndim), (a.shape, a.dtype, 3))
            np.testing.assert_array_equal(np.asarray(k), a)
            np.testing.assert_array_equal(crop, a[1:3, 2:5])
            crop[0, 0, 0] = 7  # a copy: the cache stays as written
        np.testing.assert_array_equal(np.asarray(kept[0]), arrays[0])
        self.assertIn("on disk", store.describe())
        del kept
        store.close()
        self.assertFalse(os.path.exists(folder))

    def test_memory_hands_back_the_array_and_writes_nothing(self):
        import teacher_store

        folder = os.path.join(tempfile.mkdtemp(prefix="ism_store_"), "teacher_cache")
        store = teacher_store.TeacherStore("auto", folder, 3, available_bytes=1 << 30)
        a = np.zeros((8, 8, 21), np.float16)
        self.assertIs(store.keep(0, a), a)
        self.assertFalse(os.path.exists(folder))
        self.assertIn("0.0 GB held in memory", store.describe())
        small = teacher_store.TeacherStore("auto", folder, 3, available_bytes=a.nbytes)
        self.assertIsInstance(small.keep(0, a), teacher_store.StoredArray)  # 3 > a quarter
        small.close()

    def test_the_training_reads_the_same_targets_from_either_place(self):
        require_torch(self)
        import adapt_segmentation as adapt
        import augment
        import teacher_store

        torch.manual_seed(0)
        model = torch.nn.Conv2d(3, labels.NUM_TRAIN_IDS + 1, 3, padding=1)

        def samples():
            out = []
            for i in range(3):
                target = np.full((16, 24), labels.IGNORE, np.uint8)
                target[10:, :] = i
                image = np.random.default_rng(i).integers(0, 255, (16, 24, 3), dtype=np.uint8)
                out.append(datasets.Sample(f"s{i}", "dense", image, target))
            return out

        folder = os.path.join(tempfile.mkdtemp(prefix="ism_store_"), "teacher_cache")
        for soft in (True, False):
            in_memory, on_disk = samples(), samples()
            adapt.teacher_targets(in_memory, model, torch, 0.0, False, soft, labelled_weight=0.3)
            store = teacher_store.TeacherStore("disk", folder, len(on_disk))
            adapt.teacher_targets(on_disk, model, torch, 0.0, False, soft, labelled_weight=0.3,
                                  store=store)
            for m, d in zip(in_memory, on_disk):
                self.assertIsInstance(d.teacher, teacher_store.StoredArray)
                np.testing.assert_array_equal(m.teacher, np.asarray(d.teacher))
                dtype = np.float32 if soft else None
                a = augment.random_crop(m, np.random.default_rng(2), 8, 12, dtype)
                b = augment.random_crop(d, np.random.default_rng(2), 8, 12, dtype)
                for x, y in zip(a, b):  # image, target, teacher: one crop from either place
                    np.testing.assert_array_equal(x, y)
            for d in on_disk:
                d.teacher = None
            store.close()


class Crops(unittest.TestCase):
    """The training crop reads only its window of the teacher, as a whole resize would give it."""

    def test_the_window_is_what_opencv_nearest_resize_then_crop_gives(self):
        import cv2

        import augment

        rng = np.random.default_rng(3)
        for trial in range(300):
            h0, w0 = int(rng.integers(8, 400)), int(rng.integers(8, 1300))
            channels = (1, 3, 21)[trial % 3]
            source = rng.integers(0, 255, (h0, w0, channels)).astype(np.float32)
            if channels == 1:
                source = source[..., 0].astype(np.uint8)
            s = rng.uniform(0.5, 1.6)
            h, w = max(8, int(round(h0 * s))), max(8, int(round(w0 * s)))
            crop_h, crop_w = int(rng.integers(1, h + 1)), int(rng.integers(1, w + 1))
            y, x = int(rng.integers(0, h - crop_h + 1)), int(rng.integers(0, w - crop_w + 1))
            whole = cv2.resize(source, (w, h), interpolation=cv2.INTER_NEAREST_EXACT)
            np.testing.assert_array_equal(
                augment.nearest_window(source, h, w, y, x, crop_h, crop_w),
                whole[y:y + crop_h, x:x + crop_w], err_msg=f"{w0}x{h0} -> {w}x{h} at {x},{y}")

    def test_labels_and_teacher_stay_on_the_image_through_a_rescale(self):
        """A step edge rescaled as random_crop rescales the image (INTER_AREA down, INTER_LINEAR
        up: pixel centres), its labels and its teacher as random_crop rescales them: the label
        edge sits on the image's (the area left of the edge) within half a pixel, and on average
        within a twentieth. Plain INTER_NEAREST put it half a pixel right on average, up to one."""
        import cv2

        import augment

        rng = np.random.default_rng(5)
        label_offsets, teacher_offsets = [], []
        for _ in range(400):
            w0 = int(rng.integers(60, 400))
            edge = int(rng.integers(10, w0 - 10))
            step = np.zeros((3, w0), np.uint8)
            step[:, edge:] = 1
            s = rng.uniform(0.5, 1.6)
            w = max(8, int(round(w0 * s)))
            image = cv2.resize(step.astype(np.float32), (w, 3),
                               interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
            image_edge = float((1.0 - image[0]).sum())
            target = augment._resize_labels(step, w, 3, sparse=False)
            teacher = augment.nearest_window(step, 3, w, 0, 0, 3, w)
            label_offsets.append(int(np.argmax(target[0] > 0)) - image_edge)
            teacher_offsets.append(int(np.argmax(teacher[0] > 0)) - image_edge)
        for name, offsets in (("labels", label_offsets), ("teacher", teacher_offsets)):
            self.assertLessEqual(np.abs(offsets).max(), 0.5 + 1e-3, name)
            self.assertLess(abs(np.mean(offsets)), 0.05, name)

    def test_crops_larger_than_the_image_pad_the_teacher_empty(self):
        import augment

        target = np.zeros((10, 12), np.uint8)
        sample = datasets.Sample("s", "dense", np.zeros((10, 12, 3), np.uint8), target)
        sample.teacher = np.ones((10, 12, 4), np.float16)
        _, target, teacher = augment.random_crop(sample, np.random.default_rng(0), 20, 30,
                                                 np.float32)
        self.assertEqual(teacher.shape, (20, 30, 4))
        self.assertEqual(teacher.dtype, np.float32)
        self.assertTrue((teacher.sum(axis=2) == 0).any())  # padded: nothing taught there
        self.assertTrue((teacher.sum(axis=2) == 4).any())
        self.assertTrue((target == labels.IGNORE).any())


class RareObjectPaste(unittest.TestCase):
    """--paste-rare: regions of rare-class labels cut from the dense frames, pasted into crops."""

    PERSON, BICYCLE, BUS, ROAD = 11, 18, 15, 0

    def frame(self, kind="dense"):
        target = np.full((40, 60), self.ROAD, np.uint8)
        target[5:25, 10:18] = self.PERSON  # 160 pixels
        target[20:30, 18:26] = self.BICYCLE  # 80 more, touching the person: one cyclist
        target[35:38, 50:53] = self.BUS  # 9 stray pixels
        image = np.zeros((40, 60, 3), np.uint8)
        image[target == self.PERSON] = (0, 0, 200)
        image[target == self.BICYCLE] = (0, 200, 0)
        return datasets.Sample("f", kind, image, target)

    def test_a_touching_region_is_one_object_and_stray_pixels_and_sparse_frames_are_not(self):
        import augment

        ids = [self.PERSON, self.BICYCLE, self.BUS]
        objects = augment.cut_objects([self.frame(), self.frame("sparse")], ids)
        self.assertEqual(len(objects), 1)
        obj = objects[0]
        self.assertEqual(obj.target.shape, (25, 16))  # rows 5-29, columns 10-25
        self.assertEqual(int((obj.target == self.PERSON).sum()), 160)
        self.assertEqual(int((obj.target == self.BICYCLE).sum()), 80)
        # The box's corner outside both regions is road in the frame: not part of the object.
        self.assertEqual(obj.target[0, 15], labels.IGNORE)
        self.assertEqual(obj.image[0, 0].tolist(), [0, 0, 200])

    def test_pasted_pixels_take_the_labels_and_the_teacher_teaches_nothing_there(self):
        import augment

        obj = augment.cut_objects([self.frame()], [self.PERSON, self.BICYCLE])[0]
        image = np.full((50, 80, 3), 90, np.uint8)
        target = np.full((50, 80), self.ROAD, np.uint8)
        soft = np.ones((50, 80, 4), np.float32)
        hard = np.full((50, 80), self.ROAD, np.uint8)
        for teacher in (soft, hard):
            im, tg = image.copy(), target.copy()
            augment.paste_objects(im, tg, teacher, [obj], np.random.default_rng(5), 1,
                                  scale_range=(1.0, 1.0))
            pasted = tg != self.ROAD
            self.assertEqual(int(pasted.sum()), 240)  # the cyclist's pixels, nothing else
            self.assertTrue(np.all(im[pasted].sum(axis=1) == 200))  # its colours came along
            self.assertTrue(np.all(im[~pasted] == 90))
            if teacher.ndim == 3:
                np.testing.assert_array_equal(teacher[..., -1] == 0, pasted)
                self.assertTrue(np.all(teacher[..., :-1] == 1))  # only the weight changes
            else:
                np.testing.assert_array_equal(teacher == labels.IGNORE, pasted)

    def test_an_object_larger_than_the_crop_is_skipped(self):
        import augment

        obj = augment.cut_objects([self.frame()], [self.PERSON, self.BICYCLE])[0]
        image, target = np.zeros((10, 80, 3), np.uint8), np.zeros((10, 80), np.uint8)
        teacher = np.ones((10, 80, 4), np.float32)
        augment.paste_objects(image, target, teacher, [obj], np.random.default_rng(0), 3)
        self.assertTrue(np.all(target == 0) and np.all(teacher == 1))

    def test_the_paster_pastes_at_its_probability_and_is_absent_at_zero(self):
        import augment
        import adapt_segmentation as adapt

        frames = [self.frame()]
        self.assertIsNone(adapt.rare_object_paster(frames, 0.0))  # no draw a run did not make
        paste = adapt.rare_object_paster(frames, 1.0)
        rng = np.random.default_rng(1)
        frames[0].teacher = np.ones((40, 60, 4), np.float16)
        image, target = frames[0].image.copy(), frames[0].target.copy()
        changed = 0
        for trial in range(20):  # as training calls it (float32) and unconverted
            _, _, teacher = augment.random_crop(frames[0], rng, 40, 60,
                                                np.float32 if trial % 2 else None,
                                                scale_range=(1.0, 1.0), paste=paste)
            changed += int((teacher[..., -1] == 0).any())
        self.assertEqual(changed, 20)
        # The crop is pasted in place: the sample itself is left alone.
        self.assertTrue(np.all(frames[0].teacher == 1))
        np.testing.assert_array_equal(frames[0].image, image)
        np.testing.assert_array_equal(frames[0].target, target)

    def test_a_probability_outside_zero_to_one_is_refused_naming_the_option(self):
        import adapt_segmentation as adapt

        with self.assertRaises(SystemExit) as e:
            adapt.main(["--shared", "/nonexistent", "--paste-rare", "1.5"])
        self.assertIn("--paste-rare", str(e.exception))


class WeightInterpolation(unittest.TestCase):
    """Weight-space ensembling of the adapted network with its base (--interpolate)."""

    def setUp(self):
        require_torch(self)

    def test_floats_move_by_the_factor_and_the_batch_counter_is_the_adapted_one(self):
        import torch
        import adapt_segmentation as adapt

        base = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 1), torch.nn.BatchNorm2d(4)).state_dict()
        adapted = {k: (v + 4.0 if v.is_floating_point() else v + 7) for k, v in base.items()}
        half = adapt.interpolate_weights(base, adapted, 0.25)
        for key, value in base.items():
            if value.is_floating_point():
                self.assertTrue(torch.allclose(half[key], value + 1.0), key)
            else:
                self.assertTrue(torch.equal(half[key], adapted[key]), key)
        for alpha, expect in ((0.0, base), (1.0, adapted)):
            out = adapt.interpolate_weights(base, adapted, alpha)
            for key in base:
                if base[key].is_floating_point():
                    self.assertTrue(torch.allclose(out[key], expect[key]), (alpha, key))
        with self.assertRaisesRegex(ValueError, "1.weight"):
            adapt.interpolate_weights({k: v for k, v in base.items() if k != "1.weight"},
                                      adapted, 0.5)

    def test_the_factors_are_checked_and_named_in_the_error(self):
        import adapt_segmentation as adapt

        self.assertEqual(adapt.interpolation_factors("0.5, 1"), [0.5, 1.0])
        for bad in ("0.5,x", "1.5", "-0.1", ""):
            with self.assertRaises(SystemExit) as caught:
                adapt.interpolation_factors(bad)
            self.assertIn("--interpolate", str(caught.exception))

    def test_the_best_validated_factor_is_chosen_and_left_in_the_model(self):
        import torch
        import adapt_segmentation as adapt

        model = torch.nn.Linear(1, 1, bias=False)
        with torch.no_grad():
            model.weight.fill_(1.0)  # adapted: 1, base: 0, so the weight is the factor
        base = {"weight": torch.zeros(1, 1)}
        real_validate = adapt.validate
        # A validation that peaks at weight 0.3: of 0, 0.5 and 1 the best is 0.5.
        adapt.validate = lambda m, t, v: {"dense_pixel_accuracy": 0.0, "sparse_point_accuracy": 0.0,
                                          "miou": -(m.weight.item() - 0.3) ** 2}
        try:
            chosen, scored = adapt.choose_interpolation(model, torch, base, [], [0.0, 0.5, 1.0])
            self.assertEqual(chosen["alpha"], 0.5)
            self.assertAlmostEqual(chosen["miou"], -0.04)
            self.assertAlmostEqual(model.weight.item(), 0.5)
            self.assertEqual([s["alpha"] for s in scored], [0.0, 0.5, 1.0])
            # Equal scores: the first given wins (the list's order is the user's preference).
            adapt.validate = lambda m, t, v: {"dense_pixel_accuracy": 0.0,
                                              "sparse_point_accuracy": 0.0, "miou": 0.4}
            model.weight.data.fill_(1.0)
            chosen, _ = adapt.choose_interpolation(model, torch, base, [], [1.0, 0.5])
            self.assertEqual(chosen["alpha"], 1.0)
            self.assertAlmostEqual(model.weight.item(), 1.0)
        finally:
            adapt.validate = real_validate


class WeightAveraging(unittest.TestCase):
    """The mean of the weights over the end of a run (--average-weights)."""

    def setUp(self):
        require_torch(self)

    def test_floats_are_the_running_mean_and_the_batch_counter_the_latest(self):
        import torch
        import weight_average

        net = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 1), torch.nn.BatchNorm2d(4)).double()
        first = {k: v.clone() for k, v in net.state_dict().items()}
        average = weight_average.WeightAverage()
        for shift in (1.0, 2.0, 6.0):
            average.add({k: (v + shift if v.is_floating_point() else v + int(shift))
                         for k, v in first.items()})
        self.assertEqual(average.count, 3)
        mean = average.state_dict()
        for key, value in first.items():
            self.assertEqual(mean[key].dtype, value.dtype, key)
            if value.is_floating_point():
                self.assertTrue(torch.allclose(mean[key], value + 3.0, atol=1e-5), key)
            else:
                self.assertTrue(torch.equal(mean[key], value + 6), key)
        # The mean is a copy: training on after it was taken does not move it.
        mean["0.weight"] += 100.0
        self.assertTrue(torch.allclose(average.state_dict()["0.weight"], first["0.weight"] + 3.0,
                                       atol=1e-5))

    def test_nothing_averaged_or_another_network_is_refused(self):
        import torch
        import weight_average

        average = weight_average.WeightAverage()
        with self.assertRaisesRegex(ValueError, "no weights"):
            average.state_dict()
        average.add(torch.nn.Linear(2, 2).state_dict())
        with self.assertRaisesRegex(ValueError, "other tensors"):
            average.add(torch.nn.Conv2d(2, 2, 1).state_dict() | {"extra": torch.zeros(1)})

    def test_the_mean_is_kept_only_when_it_validates_better(self):
        import torch
        import adapt_segmentation as adapt
        import weight_average

        model = torch.nn.Linear(1, 1, bias=False)
        average = weight_average.WeightAverage()
        for w in (0.2, 0.4):  # mean 0.3
            average.add({"weight": torch.full((1, 1), w)})
        out = tempfile.mkdtemp(prefix="ism_average_")
        best_path, averaged_path = (os.path.join(out, n) for n in ("best.pt", "averaged.pt"))
        real_validate = adapt.validate
        # Validation peaks at weight 0.3: the mean beats a step at 0.5, not a step at 0.3.
        adapt.validate = lambda m, t, v: {"dense_pixel_accuracy": 0.0, "sparse_point_accuracy": 0.0,
                                          "miou": -(m.weight.item() - 0.3) ** 2}
        try:
            step_at = {"step": 7, "dense_pixel_accuracy": 0.0, "sparse_point_accuracy": 0.0}
            torch.save({"weight": torch.full((1, 1), 0.5)}, best_path)
            best, averaged = adapt.keep_average_if_better(
                model, torch, [], average, 9, dict(step_at, miou=-0.04), best_path, averaged_path)
            self.assertEqual(averaged["steps_averaged"], 2)
            self.assertIs(best, averaged)
            self.assertAlmostEqual(torch.load(best_path)["weight"].item(), 0.3, places=6)
            self.assertAlmostEqual(torch.load(averaged_path)["weight"].item(), 0.3, places=6)
            torch.save({"weight": torch.full((1, 1), 0.3)}, best_path)
            best, averaged = adapt.keep_average_if_better(
                model, torch, [], average, 9, dict(step_at, miou=0.0), best_path, averaged_path)
            self.assertEqual(best["step"], 7)
            self.assertNotIn("steps_averaged", best)
        finally:
            adapt.validate = real_validate

    def test_keep_last_exports_the_last_weights_even_when_a_step_validated_better(self):
        import torch
        import adapt_segmentation as adapt

        model = torch.nn.Linear(1, 1, bias=False)
        with torch.no_grad():
            model.weight.fill_(0.5)
        best_path = os.path.join(tempfile.mkdtemp(prefix="ism_keep_"), "best.pt")
        torch.save({"weight": torch.full((1, 1), 0.3)}, best_path)  # a better step's
        last = {"step": 9, "miou": 0.1}
        self.assertIs(adapt.keep_last_weights(model, torch, last, None, best_path), last)
        self.assertAlmostEqual(torch.load(best_path)["weight"].item(), 0.5, places=6)
        averaged = {"step": 9, "steps_averaged": 4, "miou": 0.2}
        self.assertIs(adapt.keep_last_weights(model, torch, last, averaged, best_path), averaged)

    def test_a_run_that_kept_the_base_network_says_so_and_how_to_avoid_it(self):
        import adapt_segmentation as adapt

        note = adapt.kept_weights_note({"step": 0, "miou": 0.4252}, 300, 0.4252)
        self.assertIn("kept the weights of step 0", note)
        self.assertIn("WARNING: none of the 300 steps beat the base network", note)
        self.assertIn("--keep last", note)
        # A step that beat it, or no training at all (--minutes 0), is no warning.
        self.assertNotIn("WARNING", adapt.kept_weights_note({"step": 300, "miou": 0.43}, 300, 0.42))
        self.assertNotIn("WARNING", adapt.kept_weights_note({"step": 0, "miou": 0.42}, 0, 0.42))
        self.assertIn("mean of the last 4 steps", adapt.kept_weights_note(
            {"step": 9, "steps_averaged": 4, "miou": 0.2}, 9, 0.1))

    def test_a_fraction_outside_zero_to_one_is_refused_naming_the_option(self):
        import adapt_segmentation as adapt

        for bad in ("1", "-0.5"):
            with self.assertRaises(SystemExit) as caught:
                adapt.main(["--shared", "/nonexistent", "--average-weights", bad])
            self.assertIn("--average-weights", str(caught.exception))


class LogitCalibration(unittest.TestCase):
    """Per-class logit offsets fitted on the held-out frames (--calibrate-offsets)."""

    def setUp(self):
        require_torch(self)

    @staticmethod
    def logits_for(truth, rng, shift=None):
        """Logits that favour the true class by 2 under unit noise on the classes in truth (the
        others far below); shift[c] is added to channel c (negative: the class is
        under-predicted)."""
        logits = np.full((len(truth), labels.NUM_CLASSES), -10.0, np.float32)
        present = np.unique(truth)
        logits[:, present] = rng.normal(0.0, 1.0, (len(truth), len(present)))
        logits[np.arange(len(truth)), truth] += 2.0
        for c, v in (shift or {}).items():
            logits[:, c] += v
        logits[:, labels.BACKGROUND_CHANNEL] = -1e9
        return logits

    def test_an_under_predicted_class_gets_its_offset_back_and_the_miou_rises(self):
        import logit_calibration as cal

        rng = np.random.default_rng(3)
        truth = np.repeat(np.arange(3), 3000)
        logits = self.logits_for(truth, rng, {1: -1.5})
        offsets, before, after = cal.fit_class_offsets(logits, truth)
        self.assertGreater(after, before + 0.05)
        # Offsets are relative: class 1 is lifted against the other two by about what it lost.
        lift = offsets[1] - max(offsets[0], offsets[2])
        self.assertGreaterEqual(lift, 1.0)
        self.assertLessEqual(lift, 2.0)
        self.assertTrue(np.all(offsets[3:] == 0))
        self.assertAlmostEqual(cal.mean_iou(logits, truth, offsets), after, places=9)

    def test_only_classes_the_frames_can_measure_move(self):
        import logit_calibration as cal

        rng = np.random.default_rng(4)
        # Class 5 has too few pixels to be measured; class 11 (person) is absent but predicted
        # now and then, so pushing it down would always gain: neither may move.
        truth = np.concatenate([np.repeat([0, 1], 3000), np.full(20, 5)])
        logits = self.logits_for(truth, rng, {5: -3.0})
        logits[:200, 11] = 5.0
        offsets, _, _ = cal.fit_class_offsets(logits, truth, min_pixels=1000)
        self.assertEqual(offsets[5], 0.0)
        self.assertEqual(offsets[11], 0.0)

    def test_calibrated_logits_keep_zero_offsets(self):
        import logit_calibration as cal

        truth = np.repeat(np.arange(4), 2000)
        logits = np.full((len(truth), labels.NUM_CLASSES), -5.0, np.float32)
        logits[np.arange(len(truth)), truth] = 5.0
        offsets, before, after = cal.fit_class_offsets(logits, truth)
        self.assertTrue(np.all(offsets == 0))
        self.assertEqual(before, 1.0)
        self.assertEqual(after, 1.0)
        self.assertEqual(cal.describe(offsets), "none")

    def test_the_offsets_are_in_the_exported_graph(self):
        import cv2
        import logit_calibration as cal
        import onnx_export

        torch.manual_seed(0)
        net = torch.nn.Conv2d(3, labels.NUM_CLASSES, 3, padding=1).eval()
        offsets = np.zeros(labels.NUM_CLASSES, np.float32)
        offsets[[0, 1, 8]] = (-1.0, 0.75, 0.25)
        self.assertEqual(cal.describe(offsets), "road -1, sidewalk +0.75, vegetation +0.25")
        path = os.path.join(tempfile.mkdtemp(prefix="ism_offsets_"), "net.onnx")
        onnx_export.export_onnx(cal.with_offsets(net, offsets, torch), path, 64, 32)
        x = torch.rand(1, 3, 32, 64)
        opencv = cv2.dnn.readNetFromONNX(path)
        opencv.setInput(x.numpy())
        with torch.no_grad():
            expected = (net(x) + torch.from_numpy(offsets).view(1, -1, 1, 1)).numpy()
        self.assertLess(float(np.abs(opencv.forward() - expected).max()), 1e-4)


class LovaszLoss(unittest.TestCase):
    """The Lovasz-softmax loss (--lovasz-weight): a surrogate of 1 - IoU per class."""

    def setUp(self):
        require_torch(self)

    @staticmethod
    def one_hot(predicted, num_classes):
        import torch

        return torch.nn.functional.one_hot(predicted, num_classes).permute(0, 3, 1, 2).float()

    def test_one_hot_predictions_give_one_minus_the_mean_iou_of_the_present_classes(self):
        import torch
        import lovasz

        g = torch.Generator().manual_seed(4)
        target = torch.randint(0, 4, (2, 6, 8), generator=g)  # class 4 in no label: not averaged
        target[0, 0, :] = labels.IGNORE
        predicted = torch.randint(0, 5, (2, 6, 8), generator=g)
        loss = lovasz.lovasz_softmax(self.one_hot(predicted, 5), target, labels.IGNORE, torch)
        labelled = target != labels.IGNORE
        ious = []
        for c in range(4):
            t, p = target[labelled] == c, predicted[labelled] == c
            ious.append((t & p).sum().item() / (t | p).sum().item())
        self.assertAlmostEqual(loss.item(), 1.0 - float(np.mean(ious)), places=5)
        # Predictions at unlabelled pixels do not count.
        predicted[0, 0, :] = (predicted[0, 0, :] + 1) % 5
        again = lovasz.lovasz_softmax(self.one_hot(predicted, 5), target, labels.IGNORE, torch)
        self.assertAlmostEqual(again.item(), loss.item(), places=6)
        perfect = lovasz.lovasz_softmax(self.one_hot(target.clamp(max=4), 5), target,
                                        labels.IGNORE, torch)
        self.assertAlmostEqual(perfect.item(), 0.0, places=6)

    def test_its_gradient_raises_the_iou_of_a_small_class(self):
        import torch
        import lovasz

        # A class of 20 pixels against one of 980, all predicted as the large one: the mean
        # cross-entropy spreads its gradient over the 1000 pixels (20 such steps of it leave the
        # small class's IoU at 0); the per-class loss weighs the small class's IoU as much.
        target = torch.zeros(1, 20, 50, dtype=torch.long)
        target[0, :, :1] = 1
        logits = torch.zeros(1, 2, 20, 50)
        logits[0, 0] = 1.0
        logits.requires_grad_(True)
        optimizer = torch.optim.SGD([logits], lr=10.0)
        for _ in range(20):
            optimizer.zero_grad()
            loss = lovasz.lovasz_softmax(torch.softmax(logits, 1), target, labels.IGNORE, torch)
            loss.backward()
            optimizer.step()
        predicted = logits.argmax(1)
        small = target == 1
        iou = (small & (predicted == 1)).sum().item() / (small | (predicted == 1)).sum().item()
        self.assertGreater(iou, 0.9)

    def test_nothing_labelled_gives_zero_with_a_gradient_path(self):
        import torch
        import lovasz

        logits = torch.randn(1, 3, 4, 4, requires_grad=True)
        target = torch.full((1, 4, 4), labels.IGNORE, dtype=torch.long)
        loss = lovasz.lovasz_softmax(torch.softmax(logits, 1), target, labels.IGNORE, torch)
        self.assertEqual(loss.item(), 0.0)
        loss.backward()  # the training step must not fail on a batch without labels


class EncoderLearningRate(unittest.TestCase):
    """--encoder-lr-scale: the encoder learns slower than the decoder, or not at all."""

    def setUp(self):
        require_torch(self)

    def test_each_base_network_splits_into_its_encoder_and_decoder(self):
        import enet
        import espnetv2

        espnet = espnetv2.build_normalized_espnetv2(1.0)
        names = [n for n, _ in espnet.named_parameters()]
        encoder = [n for n in names if base_networks.get("espnetv2_s1").is_encoder(n)]
        # The whole EESPNet and nothing of the bottom-up decoder or its merges.
        self.assertEqual(encoder, [n for n in names if ".base_net." in n])
        self.assertTrue(any(n.startswith("net.bu_dec_l4.") for n in set(names) - set(encoder)))
        self.assertEqual(base_networks.get("espnetv2_s2").is_encoder,
                         base_networks.get("espnetv2_s1").is_encoder)

        class Wrapped(torch.nn.Module):  # base_networks' TrainIdOrder wraps ENet as .net
            def __init__(self):
                super().__init__()
                self.net = enet.build_enet()

        names = [n for n, _ in Wrapped().named_parameters()]
        encoder = [n for n in names if base_networks.get("enet").is_encoder(n)]
        stages = ("net.initial.", "net.bottleneck1_", "net.bottleneck2_", "net.bottleneck3_")
        self.assertEqual(encoder, [n for n in names if n.startswith(stages)])
        self.assertIn("net.fullconv.weight", set(names) - set(encoder))
        self.assertTrue(any(n.startswith("net.bottleneck4_0.") for n in names))
        self.assertFalse(any(n.startswith("net.bottleneck4_") for n in encoder))

    def toy(self):
        torch.manual_seed(0)
        model = torch.nn.Sequential()
        model.add_module("enc", torch.nn.Linear(3, 3))
        model.add_module("dec", torch.nn.Linear(3, 2))
        return model

    def step(self, model, scale):
        import adapt_segmentation as adapt

        groups = adapt.parameter_groups(model, lambda n: n.startswith("enc."), scale)
        optimizer = torch.optim.AdamW(groups, lr=0.01, weight_decay=0.0)
        for group in optimizer.param_groups:  # as the training loop sets it
            group["lr"] = 0.01 * group["lr_scale"]
        before = {n: p.detach().clone() for n, p in model.named_parameters()}
        model(torch.randn(5, 3)).pow(2).sum().backward()
        optimizer.step()
        return {n: (p.detach() - before[n]).abs() for n, p in model.named_parameters()}

    def test_the_encoder_moves_by_the_scale_and_not_at_all_when_frozen(self):
        model = self.toy()
        moved = self.step(model, 0.1)
        # Adam's first step moves every parameter with a gradient by its learning rate.
        self.assertTrue(torch.allclose(moved["dec.weight"], torch.full((2, 3), 0.01), atol=1e-6))
        self.assertTrue(torch.allclose(moved["enc.weight"], torch.full((3, 3), 0.001), atol=1e-6))

        model = self.toy()
        moved = self.step(model, 0.0)
        self.assertEqual(float(moved["enc.weight"].max()), 0.0)
        self.assertEqual(float(moved["enc.bias"].max()), 0.0)
        self.assertFalse(model.enc.weight.requires_grad)  # no backward through it at all
        self.assertTrue(torch.allclose(moved["dec.bias"], torch.full((2,), 0.01), atol=1e-6))

    def test_a_network_without_an_encoder_is_refused(self):
        import adapt_segmentation as adapt

        with self.assertRaisesRegex(SystemExit, "encoder-lr-scale.*0 / 4"):
            adapt.parameter_groups(self.toy(), lambda n: False, 0.5)

    def test_a_negative_scale_is_refused_naming_the_option(self):
        import adapt_segmentation as adapt

        with self.assertRaises(SystemExit) as e:
            adapt.main(["--shared", "/nonexistent", "--encoder-lr-scale", "-0.5"])
        self.assertIn("--encoder-lr-scale -0.5", str(e.exception))


class AdaptationTradePlot(unittest.TestCase):
    """scripts/plot_adaptation_trade.py: the runs table read strictly, the figure written."""

    def run_plot(self, text):
        sys.path.insert(0, os.path.join(REPO_ROOT, "scripts"))
        import plot_adaptation_trade as trade

        tmp = tempfile.mkdtemp()
        runs = os.path.join(tmp, "runs.csv")
        with open(runs, "w") as f:
            f.write(text)
        output = os.path.join(tmp, "trade.png")
        trade.main(["--runs", runs, "--output", output])
        return runs, output

    def test_the_table_becomes_a_figure(self):
        runs, output = self.run_plot("# a comment\nlabel,kind,raw_05,raw_08,section,from\n"
                                     "base,base,0.74,0.78,x\nrun,adapted,0.88,0.73,y\n"
                                     "run calibrated,calibrated,0.89,0.73,z,run\n")
        with open(output, "rb") as f:
            self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")
        import plot_adaptation_trade as trade

        self.assertEqual([r["from"] for r in trade.read_runs(runs)], [None, None, 1])

    def test_a_bad_row_is_named_by_its_file_line(self):
        header = "# comment\nlabel,kind,raw_05,raw_08,section,from\nok,base,0.7,0.7,x\n"
        for row, what in (("bad,adapted,0.8x,0.7,y\n", r"runs\.csv:4: raw_05 and raw_08 must"),
                          ("bad,teacher,0.8,0.7,y\n", r"runs\.csv:4: kind 'teacher'"),
                          ("bad,calibrated,0.8,0.7,y,later\n", r"runs\.csv:4: from 'later'"),
                          ("bad,adapted,0.8,0.7,y,ok,z\n", r"runs\.csv:4: more fields")):
            with self.assertRaises(SystemExit) as caught:
                self.run_plot(header + row)
            self.assertRegex(str(caught.exception), what)


class ClassIouPlot(unittest.TestCase):
    """scripts/plot_class_iou.py: evaluate_semantics JSON results read strictly, one panel per
    sequence and variant with the first result's classes."""

    @staticmethod
    def result(road_iou, person_truth=20):
        def scores(iou):
            return {"miou": iou, "classes": {
                "road": {"truth": 100, "iou": iou},
                "person": {"truth": person_truth, "iou": 0.5},
                "truck": {"truth": 0, "iou": 0},  # predicted only: not a class of the truth
            }}
        in_map = scores(road_iou + 0.1)
        in_map["classes"]["person"]["truth"] = person_truth // 4  # the rest in unclassed voxels
        return {"sequences": {"seq/05": {"variants": {"raw": scores(road_iou)}, "map": in_map}}}

    def write(self, tmp, name, content):
        path = os.path.join(tmp, name)
        with open(path, "w") as f:
            f.write(content if isinstance(content, str) else json.dumps(content))
        return path

    def setUp(self):
        sys.path.insert(0, os.path.join(REPO_ROOT, "scripts"))

    def test_two_networks_become_panels_of_the_classes_with_labelled_points(self):
        import plot_class_iou as plot

        tmp = tempfile.mkdtemp()
        a = self.write(tmp, "a.json", self.result(0.6))
        b = self.write(tmp, "b.json", self.result(0.8, person_truth=0))
        results = [plot.read_result(f"enet={a}"), plot.read_result(f"adapted={b}")]
        panels = plot.panels(results, ["raw", "map"])
        self.assertEqual([(p[0], p[1]) for p in panels], [("seq/05", "raw"), ("seq/05", "map")])
        seq, variant, classes, rows, truth = panels[1]
        self.assertEqual(classes, ["road", "person"])  # the first result's truth decides
        self.assertEqual(truth, [100, 20])  # every point of the class, as the raw labels count
        self.assertEqual([r[0] for r in rows], ["enet", "adapted"])
        self.assertAlmostEqual(rows[1][2][0], 0.9)  # adapted's map road IoU
        output = os.path.join(tmp, "classes.png")
        plot.main([f"enet={a}", f"adapted={b}", "--output", output])
        with open(output, "rb") as f:
            self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")
        self.assertEqual(os.listdir(tmp).count("classes.png.tmp.png"), 0)

    def test_bad_results_are_named_by_their_file_or_network(self):
        import plot_class_iou as plot

        tmp = tempfile.mkdtemp()
        good = self.write(tmp, "good.json", self.result(0.6))
        cut = self.write(tmp, "cut.json", '{\n  "sequences": ')
        cases = (
            (["no-equals-sign"], r"'no-equals-sign': expected NAME=RESULT.json"),
            ([f"x={tmp}/missing.json"], r"missing\.json: No such file"),
            ([f"x={cut}"], r"cut\.json:2: not JSON"),
            ([f"x={self.write(tmp, 'other.json', {'frames': 3})}"],
             r"other\.json: not an evaluate_semantics --json result"),
            ([f"x={self.write(tmp, 'flat.json', {'sequences': {'seq/05': 0.5}})}"],
             r"flat\.json: sequence seq/05 has no 'variants'"),
            ([f"a={good}", "--variants", "conf=0.9"],
             r"a: sequence seq/05 has no variant 'conf=0.9' \(it has raw, map\)"),
        )
        for argv, what in cases:
            with self.assertRaises(SystemExit) as caught:
                plot.main(argv + ["--output", os.path.join(tmp, "x.png")])
            self.assertRegex(str(caught.exception), what)
        other = self.result(0.6)
        other["sequences"] = {"seq/08": other["sequences"]["seq/05"]}
        with self.assertRaises(SystemExit) as caught:
            plot.panels([plot.read_result(f"a={good}"),
                         plot.read_result(f"b={self.write(tmp, 'o.json', other)}")], ["raw"])
        self.assertIn("b: no sequence seq/05 (it has seq/08)", str(caught.exception))


class Preprocessing(unittest.TestCase):
    def test_standardization_reaches_the_target_statistics(self):
        # Two colours, half the pixels each: every channel maps to exactly mean -+ std, inside
        # 0..255 (a wider image would saturate and shift the statistics).
        bgr = np.empty((60, 80, 3), np.uint8)
        bgr[:, :40] = (30, 100, 200)
        bgr[:, 40:] = (60, 140, 250)
        out = preprocess.standardize_colors(bgr)
        for c in range(3):  # BGR channel c is RGB channel 2 - c
            self.assertAlmostEqual(out[..., c].mean(), preprocess.CITYSCAPES_RGB_MEAN[2 - c],
                                   delta=0.6)
            self.assertAlmostEqual(out[..., c].std(), preprocess.CITYSCAPES_RGB_STD[2 - c],
                                   delta=0.6)
            self.assertLess(out[:, 0, c].mean(), out[:, -1, c].mean())  # the order is kept

    def test_gamma_lifts_the_midtones_and_keeps_the_ends(self):
        ramp = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, axis=2)
        out = preprocess.apply_gamma(ramp, 0.7)
        self.assertEqual(out[0, 0, 0], 0)
        self.assertEqual(out[15, 15, 0], 255)
        self.assertEqual(out.reshape(-1, 3)[128, 0], round(255 * (128 / 255) ** 0.7))


def write_tiny_semantickitti_sequence(seq):
    """A one-frame SemanticKITTI sequence folder: two labelled points straight ahead at 10 m,
    road at pixel (100, 50) and sidewalk at (80, 70) of a 200x100 image_2."""
    import cv2

    for sub in ("velodyne", "labels", "image_2"):
        os.makedirs(os.path.join(seq, sub))
    with open(os.path.join(seq, "calib.txt"), "w") as f:
        for p in ("P0", "P1", "P2", "P3"):
            f.write(f"{p}: 100 0 100 0 0 100 50 0 0 0 1 0\n")
        f.write("Tr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n")  # velodyne x forward = camera z
    np.array([[10, 0, 0, 0], [10, 2, -2, 0]], np.float32).tofile(
        os.path.join(seq, "velodyne", "000000.bin"))
    np.array([40 | (5 << 16), 48], np.uint32).tofile(os.path.join(seq, "labels", "000000.label"))
    cv2.imwrite(os.path.join(seq, "image_2", "000000.png"), np.full((100, 200, 3), 120, np.uint8))


class OwnSemanticKitti(unittest.TestCase):
    """A user's SemanticKITTI sequence: make_camera_labels writes the sparse layout, and
    --sparse-root / --dense-root make the training read it instead of ../shared."""

    def test_make_camera_labels_output_is_read_through_the_root_options(self):
        import cv2
        import e2e_support
        import adapt_segmentation as adapt

        [tool] = e2e_support.require_executables(self, "make_camera_labels")
        with tempfile.TemporaryDirectory() as tmp:
            seq = os.path.join(tmp, "semantickitti", "sequences", "00")
            write_tiny_semantickitti_sequence(seq)
            sparse_root = os.path.join(tmp, "camera_labels")
            run = subprocess.run([tool, "--sequence", seq, "--output",
                                  os.path.join(sparse_root, "sequences", "00")],
                                 capture_output=True, text=True)
            self.assertEqual(run.returncode, 0, run.stdout + run.stderr)

            dense_root = os.path.join(tmp, "dense")
            for sub in ("image_2", "semantic"):
                os.makedirs(os.path.join(dense_root, sub))
            cv2.imwrite(os.path.join(dense_root, "image_2", "000000_10.png"),
                        np.full((100, 200, 3), 90, np.uint8))
            cv2.imwrite(os.path.join(dense_root, "semantic", "000000_10.png"),
                        np.full((100, 200), 26, np.uint8))  # car everywhere

            args = adapt.parse_args(["--shared", os.path.join(tmp, "no_shared"),
                                     "--sparse-root", sparse_root, "--sparse-sequences", "00",
                                     "--val-sequence", "", "--dense-root", dense_root,
                                     "--dense-val-every", "1"])
            train, val, counts = adapt.load_samples(args, args.shared, 200, 100, True, None)
            self.assertEqual(counts["sparse"], 1)
            [sparse] = [s for s in train if s.kind == "sparse"]
            road, sidewalk, car = labels.semantickitti_to_train_id_lut()[[40, 48, 10]]
            self.assertEqual(sparse.target[50, 100], road)
            self.assertEqual(sparse.target[70, 80], sidewalk)
            self.assertEqual(int((sparse.target != labels.IGNORE).sum()), 2)
            self.assertEqual([s.kind for s in val], ["dense"])
            self.assertTrue((val[0].target == car).all())

            # An evaluation sequence stays refused under any root.
            with self.assertRaisesRegex(datasets.DatasetError, "05 is an evaluation sequence"):
                datasets.load_sparse(sparse_root, ["05"], 200, 100, 0.7, True)


class SemanticKittiDownload(unittest.TestCase):
    """--semantickitti DIR: every labelled sequence of the download but 05 / 08 converted by
    make_camera_labels and trained on, one held out."""

    def test_the_labelled_sequences_but_the_evaluation_ones_are_converted_and_read(self):
        import e2e_support
        import adapt_segmentation as adapt

        e2e_support.require_executables(self, "make_camera_labels")
        with tempfile.TemporaryDirectory() as tmp:
            root = os.path.join(tmp, "dataset")
            for seq in ("00", "01", "05", "08"):
                write_tiny_semantickitti_sequence(os.path.join(root, "sequences", seq))
            os.makedirs(os.path.join(root, "sequences", "11", "velodyne"))  # no labels: test set
            out = os.path.join(tmp, "out")
            args = adapt.parse_args(["--shared", os.path.join(tmp, "no_shared"), "--output", out,
                                     "--semantickitti", root, "--semantickitti-every", "1"])
            adapt.use_semantickitti_download(args)
            # 06 (the default validation sequence) is not there: the last one is held out.
            self.assertEqual((args.sparse_sequences, args.val_sequence), ("00", "01"))
            self.assertEqual(args.sparse_root, os.path.join(out, "camera_labels"))
            self.assertEqual(sorted(os.listdir(os.path.join(out, "camera_labels", "sequences"))),
                             ["00", "01"])
            samples = datasets.load_sparse(args.sparse_root, ["00"], 200, 100, 0.7, True)
            self.assertEqual(len(samples), 1)
            self.assertEqual(int((samples[0].target != labels.IGNORE).sum()), 2)

            both = adapt.parse_args(["--shared", tmp, "--output", out, "--semantickitti", root,
                                     "--sparse-root", out])
            with self.assertRaisesRegex(SystemExit, "--semantickitti and --sparse-root"):
                adapt.use_semantickitti_download(both)

    def test_sequences_validation_and_tool_errors_are_named(self):
        import semantickitti_download as download

        with tempfile.TemporaryDirectory() as tmp:
            with self.assertRaisesRegex(download.DownloadError, "no sequences/ folder"):
                download.trainable_sequences(tmp)
            for seq in ("05", "08"):
                write_tiny_semantickitti_sequence(os.path.join(tmp, "sequences", seq))
            with self.assertRaisesRegex(download.DownloadError, "data_odometry_color"):
                download.trainable_sequences(tmp)
            tool = os.path.join(tmp, "failing_tool")
            with open(tool, "w") as f:
                f.write("#!/bin/sh\necho 'calib.txt: no Tr line' >&2\nexit 3\n")
            os.chmod(tool, 0o755)
            with self.assertRaisesRegex(download.DownloadError,
                                        r"sequence 02 \(exit 3\):\ncalib.txt: no Tr line"):
                download.convert(tmp, ["02"], os.path.join(tmp, "out"), 10, tool, lambda m: None)
            # The workspace scripts/env.sh names (ISM_BIN) before the repository's own .ws.
            os.environ["ISM_BIN"], saved = tmp, os.environ.get("ISM_BIN")
            try:
                os.rename(tool, os.path.join(tmp, "make_camera_labels"))
                self.assertEqual(download.find_make_camera_labels("/nonexistent"),
                                 os.path.join(tmp, "make_camera_labels"))
            finally:
                os.environ.pop("ISM_BIN")
                if saved is not None:
                    os.environ["ISM_BIN"] = saved
        self.assertEqual(download.split_validation(["00", "06", "07"], "06"), (["00", "07"], "06"))
        self.assertEqual(download.split_validation(["00"], "06"), (["00"], ""))


def write_tiny_dense_root(root, frames, size=(64, 32)):
    """A KITTI semantics layout (image_2/, semantic/) of `frames` frames: road below, sky above."""
    import cv2

    for sub in ("image_2", "semantic"):
        os.makedirs(os.path.join(root, sub))
    w, h = size
    for i in range(frames):
        image = np.full((h, w, 3), 60 + 20 * i, np.uint8)
        image[h // 2:] = 120
        label = np.full((h, w), 23, np.uint8)  # sky
        label[h // 2:] = 7  # road
        cv2.imwrite(os.path.join(root, "image_2", f"{i:06d}_10.png"), image)
        cv2.imwrite(os.path.join(root, "semantic", f"{i:06d}_10.png"), label)


def require_base_weights(test):
    """The shared folder, skipping the test (loudly) without espnetv2_s2's weights."""
    shared = shared_dir()
    if not os.path.exists(os.path.join(shared, base_networks.get("espnetv2_s2").weights)):
        skip_loudly(test, "shared espnetv2_s2 weights not found")
    return shared


class OptionChecks(unittest.TestCase):
    """Options refused right after parsing (before any data is read: --shared does not even
    exist here), each error naming the option."""

    def refused(self, *options):
        import adapt_segmentation as adapt

        with self.assertRaises(SystemExit) as e:
            adapt.main(["--shared", "/nonexistent", "--output", "/nonexistent/out", *options])
        return str(e.exception)

    def test_numbers_out_of_range_name_their_option(self):
        self.assertIn("--dense-val-every 0: must be 1 or more", self.refused("--dense-val-every",
                                                                             "0"))
        self.assertIn("--temperature 0.0: must be above 0", self.refused("--temperature", "0"))
        self.assertIn("--temperature -2.0", self.refused("--temperature", "-2"))
        self.assertIn("--max-images -1: must be 0 (all images) or more",
                      self.refused("--max-images", "-1"))
        self.assertIn("--distill-labelled-weight -1.0",
                      self.refused("--distill-labelled-weight", "-1"))
        # A negative step count trained for ever, whatever --minutes said; the others ended in
        # tracebacks from PyTorch or OpenCV after the data had loaded.
        self.assertIn("--max-steps -1: must be 0", self.refused("--max-steps", "-1"))
        self.assertIn("--batch 0: must be 1 or more", self.refused("--batch", "0"))
        self.assertIn("--threads 0: must be 1 or more", self.refused("--threads", "0"))

    def test_sizes_must_be_positive(self):
        import adapt_segmentation as adapt

        for text in ("0x0", "-32x160"):
            with self.assertRaises(SystemExit) as e:
                adapt.size_arg(text, "input")
            self.assertIn("both sizes must be positive", str(e.exception))
        self.assertEqual(adapt.size_arg("1024x320", "input"), (1024, 320))

    def test_the_summary_is_standard_json(self):
        import adapt_segmentation as adapt

        summary = {"validation": {"dense_pixel_accuracy": float("nan"), "miou": 0.5},
                   "history": [1.0, float("inf")]}
        text = json.dumps(adapt.without_nan(summary), allow_nan=False)
        self.assertEqual(json.loads(text)["validation"]["dense_pixel_accuracy"], None)
        self.assertEqual(json.loads(text)["history"], [1.0, None])

    def test_the_labelled_weight_defaults_to_soft_distillation_only(self):
        import adapt_segmentation as adapt

        shared = ["--shared", "/nonexistent"]
        self.assertEqual(adapt.parse_args(shared).distill_labelled_weight, 0.3)
        self.assertEqual(adapt.parse_args(shared + ["--distill", "hard"]).distill_labelled_weight,
                         0.0)
        self.assertEqual(adapt.parse_args(shared + ["--distill-labelled-weight", "0.5"])
                         .distill_labelled_weight, 0.5)
        message = self.refused("--distill", "hard", "--distill-labelled-weight", "0.3")
        self.assertIn("--distill-labelled-weight 0.3 needs --distill soft", message)

    def test_evaluation_sequences_are_refused_however_they_are_spelt(self):
        for spelling in ("05", "05/", "./05", "x/../05", "5", "008"):
            self.assertTrue(datasets.is_evaluation_sequence(spelling), spelling)
            self.assertIn("is an evaluation sequence",
                          self.refused("--sparse-sequences", "01," + spelling))
            self.assertIn(f"--val-sequence {spelling}: SemanticKITTI",
                          self.refused("--val-sequence", spelling))
        for other in ("06", "06/", "15", "050", "seq05"):
            self.assertFalse(datasets.is_evaluation_sequence(other), other)
        with tempfile.TemporaryDirectory() as tmp:
            for seq in ("./05", "05/"):
                with self.assertRaisesRegex(datasets.DatasetError, "is an evaluation sequence"):
                    datasets.load_sparse(tmp, [seq], 64, 32, 0.7, True)

    def test_the_validation_sequence_is_not_trained_on(self):
        message = self.refused("--sparse-sequences", "01,06", "--val-sequence", "./06")
        self.assertIn("--val-sequence ./06 is also in --sparse-sequences 01,06", message)
        import semantickitti_download as download

        self.assertEqual(download.split_validation(["00", "06", "07"], "06/"),
                         (["00", "07"], "06"))

    def test_an_empty_validation_set_is_refused_before_loading_when_certain(self):
        message = self.refused("--val-sequence", "", "--max-images", "3")
        for option in ("--val-sequence", "--dense-val-every 7", "--max-images 3"):
            self.assertIn(option, message)

    def test_init_weights_are_checked_before_the_data_is_loaded(self):
        require_torch(self)
        import torch
        import adapt_segmentation as adapt

        model = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 1))
        with tempfile.TemporaryDirectory() as tmp:
            good, other, text = (os.path.join(tmp, n) for n in ("good.pt", "other.pt", "t.pt"))
            torch.save(model.state_dict(), good)
            torch.save(torch.nn.Sequential(torch.nn.Conv2d(3, 5, 1)).state_dict(), other)
            with open(text, "w") as f:
                f.write("not weights\n")
            self.assertEqual(set(adapt.load_init(good, model, "net", torch)), {"0.weight",
                                                                               "0.bias"})
            self.assertIsNone(adapt.load_init("", model, "net", torch))
            with self.assertRaisesRegex(SystemExit, "--init .*missing.pt: no such file"):
                adapt.load_init(os.path.join(tmp, "missing.pt"), model, "net", torch)
            with self.assertRaisesRegex(SystemExit, "--init .*t.pt: not a PyTorch weights file"):
                adapt.load_init(text, model, "net", torch)
            with self.assertRaisesRegex(SystemExit, r"--init .*other.pt: not weights of --base "
                                                    r"net \(wrong shape of 2 tensors"):
                adapt.load_init(other, model, "net", torch)
            # Through main: refused before the (missing) dense frames would be read.
            shared = require_base_weights(self)
            with self.assertRaises(SystemExit) as e:
                adapt.main(["--shared", shared, "--output", os.path.join(tmp, "out"),
                            "--dense-root", os.path.join(tmp, "no_dense"), "--init", other])
            self.assertIn(f"--init {other}: not weights of --base espnetv2_s2", str(e.exception))


class SparseSequenceFolders(unittest.TestCase):
    def test_a_named_sequence_without_label_images_names_its_folder(self):
        with tempfile.TemporaryDirectory() as tmp:
            seq = os.path.join(tmp, "sequences", "01")
            os.makedirs(os.path.join(seq, "image_2"))  # the raw SemanticKITTI layout: no labels_2
            with self.assertRaisesRegex(datasets.DatasetError,
                                        f"{seq}: no label images in labels_2/ or labels_3/"):
                datasets.load_sparse(tmp, ["01"], 64, 32, 0.7, True)


class DenseLabels(unittest.TestCase):
    def test_colour_label_images_are_refused_naming_the_file(self):
        # KITTI's semantic_rgb/ put where semantic/ goes: read as grey they gave luminances,
        # almost none a labelId, and the run trained on nearly no labels with exit status 0.
        import cv2

        with tempfile.TemporaryDirectory() as tmp:
            for sub in ("image_2", "semantic"):
                os.makedirs(os.path.join(tmp, sub))
            cv2.imwrite(os.path.join(tmp, "image_2", "000000_10.png"),
                        np.full((16, 32, 3), 90, np.uint8))
            colour = np.zeros((16, 32, 3), np.uint8)
            colour[:] = (128, 64, 128)  # Cityscapes' road colour
            cv2.imwrite(os.path.join(tmp, "semantic", "000000_10.png"), colour)
            with self.assertRaisesRegex(datasets.DatasetError,
                                        "000000_10.png is not one channel of 8-bit labelIds"):
                datasets.load_dense(tmp, 32, 16, 0.7, True)
            cv2.imwrite(os.path.join(tmp, "semantic", "000000_10.png"),
                        np.full((16, 32), 7, np.uint8))  # road, as labelIds
            self.assertEqual(len(datasets.load_dense(tmp, 32, 16, 0.7, True)), 1)


class MixedImageSizes(unittest.TestCase):
    """CamVid's 4:3 frames beside KITTI's: the teacher and the validation batch by image size."""

    def test_batches_hold_one_image_size(self):
        import adapt_segmentation as adapt

        images = [np.zeros(s) for s in ((32, 64, 3),) * 3 + ((32, 32, 3),) * 2]
        self.assertEqual(list(adapt.same_size_batches(images, 2)), [(0, 2), (2, 3), (3, 5)])
        self.assertEqual(list(adapt.same_size_batches(images[:4], 2)), [(0, 2), (2, 3), (3, 4)])
        self.assertEqual(list(adapt.same_size_batches(images[:3], 2)), [(0, 2), (2, 3)])
        self.assertEqual(list(adapt.same_size_batches([], 2)), [])

    def test_an_odd_kitti_count_before_camvid_frames_is_taught(self):
        require_torch(self)
        import torch
        import adapt_segmentation as adapt

        torch.manual_seed(0)
        model = torch.nn.Conv2d(3, labels.NUM_CLASSES, 1)
        samples = []
        for i, (h, w) in enumerate([(32, 64)] * 3 + [(32, 32)] * 2):
            target = np.full((h, w), labels.IGNORE, np.uint8)
            target[h // 2:] = 0
            samples.append(datasets.Sample(f"s{i}", "dense" if w == 64 else "camvid",
                                           np.full((h, w, 3), 40 * i, np.uint8), target))
        for soft in (False, True):
            adapt.teacher_targets(samples, model, torch, 0.0, False, soft, labelled_weight=0.3)
            for s in samples:
                self.assertEqual(s.teacher.shape[:2], s.target.shape)
        # A frame batched with its kind is taught as it would be alone.
        alone = datasets.Sample("x", "camvid", samples[3].image, samples[3].target)
        adapt.teacher_targets([alone], model, torch, 0.0, False, True, labelled_weight=0.3)
        np.testing.assert_allclose(alone.teacher.astype(np.float32),
                                   samples[3].teacher.astype(np.float32), atol=1e-3)
        logits = list(adapt.batched_logits(model, torch, [s.image for s in samples]))
        self.assertEqual([tuple(l.shape[-2:]) for l in logits], [(32, 64), (32, 64), (32, 32)])


class OnnxParityGate(unittest.TestCase):
    """The exported model takes its name only once it agrees with PyTorch."""

    def test_an_empty_check_is_an_error_not_a_disagreement(self):
        require_torch(self)
        import torch
        import onnx_export

        model = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 1))
        with tempfile.TemporaryDirectory() as tmp:
            path = onnx_export.export_onnx(model, os.path.join(tmp, "m.onnx"), 32, 32)
            with self.assertRaisesRegex(ValueError, "m.onnx.*0 pixels"):
                onnx_export.check_onnx_against_torch(model, path, [], 32, 32, 1)
            agreed = onnx_export.check_onnx_against_torch(
                model, path, [np.full((32, 32, 3), 90, np.uint8)], 32, 32, 1)
            self.assertEqual(agreed["pixels"], 32 * 32)

    def test_a_failed_check_leaves_no_model_where_the_tools_look(self):
        require_torch(self)
        shared = require_base_weights(self)
        from unittest import mock
        import adapt_segmentation as adapt
        import onnx_export

        with tempfile.TemporaryDirectory() as tmp:
            dense = os.path.join(tmp, "dense")
            write_tiny_dense_root(dense, 2)
            out = os.path.join(tmp, "out")
            command = ["--shared", shared, "--output", out, "--dense-root", dense,
                       "--sparse-sequences", "", "--val-sequence", "", "--dense-val-every", "2",
                       "--input", "64x32", "--export-input", "same", "--crop", "32x64",
                       "--batch", "1", "--max-steps", "1", "--threads", "1",
                       "--calibrate-offsets", "off", "--paste-rare", "0", "--rare-repeat", "0",
                       "--teacher-store", "memory"]
            os.makedirs(out)
            for stale in ("kitti_adapted.onnx", "kitti_adapted.yaml"):  # an earlier run's
                with open(os.path.join(out, stale), "w") as f:
                    f.write("stale\n")
            real = onnx_export.check_onnx_against_torch

            def disagreeing(*a, **k):
                return dict(real(*a, **k), argmax_agreement=0.5)

            with mock.patch.object(onnx_export, "check_onnx_against_torch", disagreeing):
                with self.assertRaises(SystemExit) as e:
                    adapt.main(command)
            self.assertIn("disagrees with PyTorch on 50.00%", str(e.exception))
            self.assertEqual(sorted(f for f in os.listdir(out) if "kitti_adapted" in f),
                             ["kitti_adapted.rejected.onnx"])
            self.assertTrue(os.path.exists(os.path.join(out, "summary.json")))

            summary = adapt.main(command)  # agreeing: both take their names, the rejected goes
            self.assertEqual(sorted(f for f in os.listdir(out) if "kitti_adapted" in f),
                             ["kitti_adapted.onnx", "kitti_adapted.yaml"])
            self.assertEqual(summary["val_images"], 1)
            with open(os.path.join(out, "kitti_adapted.yaml")) as f:
                self.assertIn("kitti_adapted.onnx, written by", f.read())

    def test_an_empty_validation_set_is_refused_after_loading(self):
        require_torch(self)
        shared = require_base_weights(self)
        import adapt_segmentation as adapt

        with tempfile.TemporaryDirectory() as tmp:
            dense = os.path.join(tmp, "dense")
            write_tiny_dense_root(dense, 2)
            with self.assertRaises(SystemExit) as e:
                adapt.main(["--shared", shared, "--output", os.path.join(tmp, "out"),
                            "--dense-root", dense, "--sparse-sequences", "",
                            "--val-sequence", "", "--dense-val-every", "3", "--input", "64x32",
                            "--max-steps", "1", "--threads", "1"])
            self.assertIn("no validation images: --val-sequence '' and --dense-val-every 3 over "
                          "the 2 dense frames loaded", str(e.exception))
            self.assertFalse(os.path.exists(os.path.join(tmp, "out", "best.pt")))


class OutputDefault(unittest.TestCase):
    """scripts/adapt_segmentation.sh leaves the default --output to the Python parser, so that
    every spelling of the option replaces it."""

    def test_every_spelling_of_output_is_the_one_used(self):
        import adapt_segmentation as adapt

        self.assertEqual(adapt.parse_args(["--shared", "s"]).output,
                         os.path.join(REPO_ROOT, "output", "models", "kitti"))
        for spelling in (["--output", "/tmp/x"], ["--output=/tmp/x"], ["--out", "/tmp/x"]):
            self.assertEqual(adapt.parse_args(["--shared", "s"] + spelling).output, "/tmp/x")
        with open(os.path.join(REPO_ROOT, "scripts", "adapt_segmentation.sh")) as f:
            script = f.read()
        # The arguments pass through as given: nothing appended after the user's own.
        self.assertTrue(script.rstrip().endswith(
            '/usr/bin/python3 -u "$ISM_ROOT/training/adapt_segmentation.py" "$@"'), script)
        self.assertNotIn("args+=", script)


class UsersOwnModels(unittest.TestCase):
    """Models as users bring them, through the C++ Segmenter (segment_image): the class score of
    channel c is 10 x the input's colour c, so a red, a green and a blue band must come out as the
    card's first, second and third labelId."""

    CARD = ("input: {width: 0, height: 0}\nresize_policy: pad_to_multiple\npad_multiple: %d\n"
            "mean: [0, 0, 0]\nscale: 0.00392156862745098\nswap_rb: true\n"
            "num_output_channels: 3\noutput_label_ids: [7, 26, 23]\n%s")

    def setUp(self):
        require_torch(self)
        import e2e_support
        self.segment_image = e2e_support.find_executable("segment_image")
        if self.segment_image is None:
            self.fail("segment_image not built (scripts/build.sh all)")
        self.dir = tempfile.mkdtemp(prefix="ism_user_models_")
        self.addCleanup(shutil.rmtree, self.dir, ignore_errors=True)
        import cv2
        image = np.zeros((60, 90, 3), np.uint8)  # BGR: red, green, blue bands
        image[:20, :, 2] = 255
        image[20:40, :, 1] = 255
        image[40:, :, 0] = 255
        self.image = os.path.join(self.dir, "bands.png")
        cv2.imwrite(self.image, image)

    def export(self, name, module):
        import torch
        path = os.path.join(self.dir, name + ".onnx")
        outputs = ["main", "aux"] if name == "two_outputs" else ["main"]
        torch.onnx.export(module, torch.zeros(1, 3, 64, 96), path, opset_version=11,
                          input_names=["image"], output_names=outputs,
                          dynamic_axes={"image": {2: "h", 3: "w"}})
        return path

    def run_tool(self, model, card_text):
        card = os.path.join(self.dir, "card.yaml")
        with open(card, "w") as f:
            f.write(card_text)
        out = os.path.join(self.dir, "labels.png")
        run = subprocess.run([self.segment_image, "--model", model, "--model-card", card,
                              "--input", self.image, "--output", out],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             timeout=120)
        return run, out

    def test_a_second_output_is_named_in_the_card_not_guessed(self):
        import cv2
        import torch

        class TwoOutputs(torch.nn.Module):  # an auxiliary head: the negated scores
            def forward(self, x):
                return 10 * x, -10 * x

        model = self.export("two_outputs", TwoOutputs())
        run, _ = self.run_tool(model, self.CARD % (8, ""))
        self.assertNotEqual(run.returncode, 0, run.stdout)
        self.assertIn("has 2 outputs", run.stdout)
        self.assertIn("output_name", run.stdout)
        run, _ = self.run_tool(model, self.CARD % (8, "output_name: nope\n"))
        self.assertNotEqual(run.returncode, 0, run.stdout)
        self.assertIn("output_name 'nope' is not an output", run.stdout)
        run, out = self.run_tool(model, self.CARD % (8, "output_name: main\n"))
        self.assertEqual(run.returncode, 0, run.stdout)
        labels = cv2.imread(out, cv2.IMREAD_GRAYSCALE)
        self.assertEqual([int(np.median(labels[r])) for r in (10, 30, 50)], [7, 26, 23])

    def test_a_softmax_in_the_graph_is_refused_at_load(self):
        import torch

        class Probabilities(torch.nn.Module):  # its softmax would be taken twice
            def forward(self, x):
                return torch.softmax(10 * x, dim=1)

        run, _ = self.run_tool(self.export("softmax", Probabilities()), self.CARD % (8, ""))
        self.assertNotEqual(run.returncode, 0, run.stdout)
        self.assertIn("outputs probabilities", run.stdout)
        self.assertIn("without its final softmax", run.stdout)

    def test_a_card_padding_less_than_the_network_needs_fails_at_load_naming_it(self):
        import torch

        class NeedsMultiplesOf32(torch.nn.Module):  # down by 32 and back up, added to its input
            def forward(self, x):
                low = torch.nn.functional.avg_pool2d(x, 32)
                return 10 * x + torch.nn.functional.interpolate(low, scale_factor=32.0)

        run, _ = self.run_tool(self.export("stride32", NeedsMultiplesOf32()), self.CARD % (8, ""))
        self.assertNotEqual(run.returncode, 0, run.stdout)
        self.assertIn("is pad_multiple 8 the network's own stride", run.stdout)
        run, _ = self.run_tool(self.export("stride32", NeedsMultiplesOf32()), self.CARD % (32, ""))
        self.assertEqual(run.returncode, 0, run.stdout)


class TinyPipeline(unittest.TestCase):
    """The whole command on a tiny budget: the export loads in C++ and agrees with PyTorch."""

    def test_a_few_steps_export_a_model_the_cpp_segmenter_runs_like_pytorch(self):
        require_torch(self)
        shared = shared_dir()
        needed = ["models/espnetv2-cityscapes/espnetv2_s_2.0_city_1024x512.pth",
                  "data/kitti_semantics/training", "data/semantickitti_train/sequences/06"]
        missing = [p for p in needed if not os.path.exists(os.path.join(shared, p))]
        if missing:
            skip_loudly(self, "shared data not found: " + ", ".join(missing))
        import e2e_support

        segment_image = e2e_support.find_executable("segment_image")
        if segment_image is None:
            self.fail("segment_image not built (scripts/build.sh all)")
        out = tempfile.mkdtemp(prefix="ism_adapt_")
        command = ["/usr/bin/python3", os.path.join(REPO_ROOT, "training", "adapt_segmentation.py"),
                   "--shared", shared, "--output", out, "--max-steps", "3", "--max-images", "2",
                   "--input", "512x160", "--export-input", "416x128", "--crop", "128x256",
                   "--batch", "2", "--interpolate", "0.5,1", "--average-weights", "0.7",
                   "--sparse-sequences", "01", "--val-sequence", "06", "--dense-val-every", "2",
                   "--teacher-store", "disk", "--keep", "last"]
        result = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, timeout=600)
        print(result.stdout[-3000:])
        self.assertEqual(result.returncode, 0, result.stdout[-2000:])
        # The teacher's distributions were read from disk while training, and the cache is gone.
        self.assertRegex(result.stdout, r"labels for distillation in \d+ s \(0\.\d GB on disk")
        self.assertFalse(os.path.exists(os.path.join(out, "teacher_cache")))
        for name in ("kitti_adapted.onnx", "kitti_adapted.yaml", "training.png", "summary.json"):
            self.assertTrue(os.path.exists(os.path.join(out, name)), name)
        with open(os.path.join(out, "summary.json")) as f:
            summary = json.load(f)
        self.assertEqual(summary["steps"], 3)
        # Trained at one size, exported at another: the card and the graph say the exported one.
        self.assertEqual(summary["training_input"], [512, 160])
        self.assertEqual(summary["input"], [416, 128])
        import onnx_export
        self.assertEqual(tuple(onnx_export.onnx_input_size(os.path.join(out, "kitti_adapted.onnx"))),
                         (416, 128))
        with open(os.path.join(out, "kitti_adapted.yaml")) as f:
            self.assertIn("input: {width: 416, height: 128}", f.read())
        self.assertGreaterEqual(summary["onnx_parity"]["argmax_agreement"], 0.995)
        self.assertEqual([f["alpha"] for f in summary["interpolation"]["factors"]], [0.5, 1.0])
        self.assertIn(summary["interpolation"]["chosen"], (0.5, 1.0))
        # Steps 2 and 3 of 3 lie in the last 70 % of the budget; their mean was scored.
        self.assertEqual(summary["averaged"]["steps_averaged"], 2)
        # --keep last: that mean is exported whatever the validation said of it.
        self.assertEqual(summary["best_validation"].get("steps_averaged"), 2)
        self.assertIn("kept the mean of the last 2 steps' weights", result.stdout)
        self.assertTrue(os.path.exists(os.path.join(out, "averaged.pt")))

        # The C++ Segmenter, with the card the script wrote, against PyTorch on a held-out image
        # at the exported size (labels at the image's own size, trainIds).
        import cv2

        import adapt_segmentation as adapt
        import base_networks
        image_path = os.path.join(shared, "data/semantickitti_train/sequences/06/image_2/000000.jpg")
        labels_path = os.path.join(out, "cpp_labels.png")
        run = subprocess.run([segment_image, "--model", os.path.join(out, "kitti_adapted.onnx"),
                              "--input", image_path, "--output", labels_path, "--ids", "trainid"],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             timeout=120)
        self.assertEqual(run.returncode, 0, run.stdout[-2000:])
        cpp = cv2.imread(labels_path, cv2.IMREAD_GRAYSCALE)
        image = cv2.imread(image_path)
        model = base_networks.get("espnetv2_s2").build(None)
        state = torch.load(os.path.join(out, "exported.pt"), map_location="cpu")
        model.load_state_dict(state)
        # The offsets fitted on the held-out frames are in the graph, not in exported.pt.
        calibration = summary["logit_offsets"]
        self.assertEqual(len(calibration["offsets"]), labels.NUM_CLASSES)
        self.assertGreaterEqual(calibration["miou_after"], calibration["miou_before"])
        if calibration["kept"]:
            import logit_calibration
            model = logit_calibration.with_offsets(model, calibration["offsets"], torch)
        prepared = preprocess.resize_to_input(preprocess.card_colors(image, 0.7, True), 416, 128)
        torch_labels = adapt.predict(model, torch, [prepared])[0]
        torch_labels = cv2.resize(torch_labels, (image.shape[1], image.shape[0]),
                                  interpolation=cv2.INTER_NEAREST_EXACT)
        self.assertEqual(cpp.shape, torch_labels.shape)
        agreement = float((cpp == torch_labels).mean())
        print(f"C++ Segmenter vs PyTorch on {image_path}: {agreement:.5f} of the pixels agree")
        self.assertGreaterEqual(agreement, 0.99)


if __name__ == "__main__":
    if "--gtest_output" in " ".join(sys.argv) or any(a.startswith("__name:=") for a in sys.argv):
        import rostest

        rostest.rosrun("inekf_semantic_mapping", "adapt_segmentation", "__main__")
    else:
        unittest.main()
