#!/usr/bin/python3
"""Robustness: nodes killed (SIGKILL) and respawned mid-run while the map is being saved.

A saver keeps calling ~save_map (.ot and .ply, always to the same two paths) while a checker
keeps reading those paths: at no moment may a path hold a partial or corrupt file (the saves are
atomic). semantic_octomap_node and inekf_node (~kill_nodes: with nodelets, the manager that runs
the map) are killed half-way through the bag; roslaunch respawns them; both must publish again and
the map must save again.
"""
import os
import tempfile
import threading
import time
import unittest

import rospy
import rostest

import e2e_support as e2e

NAME = "robustness_node_restart"


class NodeRestart(unittest.TestCase):
    def test_kill_and_respawn_never_corrupts_saved_map(self):
        rospy.init_node("robustness_node_restart_test")
        p = e2e.param
        duration, _, bag = e2e.synthetic_bag_from_params()
        out_dir = tempfile.mkdtemp(prefix="ism_%s_" % NAME)
        paths = {"ot": os.path.join(out_dir, "map.ot"), "ply": os.path.join(out_dir, "map.ply")}
        monitor = e2e.pipeline_monitor.PipelineMonitor()
        self.assertTrue(e2e.wait_for_subscribers(["/kitti/oxts/imu", "/kitti/velo/pointcloud"], 60),
                        "nodes did not subscribe")

        stop = threading.Event()
        corrupt, saves = [], {"ok": 0, "failed": 0}

        def check_files():
            for fmt, path in paths.items():
                try:
                    if fmt == "ot":
                        e2e.check_ot_file(path)
                    else:
                        e2e.metrics.read_ply_vertices(path)
                except FileNotFoundError:
                    pass  # not saved yet (or between a kill and the first save): fine
                except Exception as error:  # pylint: disable=broad-except
                    corrupt.append("%s: %s" % (path, error))

        def saver():
            while not stop.is_set():
                for fmt, path in paths.items():
                    try:
                        ok = e2e.save_map(path, fmt, timeout=0.5).success
                    except Exception:  # pylint: disable=broad-except  (node down / restarting)
                        ok = False
                    saves["ok" if ok else "failed"] += 1
                time.sleep(0.2)

        def checker():
            while not stop.is_set():
                check_files()
                time.sleep(0.05)

        threads = [threading.Thread(target=saver), threading.Thread(target=checker)]
        for thread in threads:
            thread.start()
        player = e2e.start_bag(bag, rate=p("rate", 1.0))
        try:
            time.sleep(e2e.CONNECT_DELAY_S + p("kill_after_s", 5.0))  # seconds into the bag
            clouds_before = monitor.summary()["topics"]["/semantic_map/labeled_cloud"]["messages"]
            odometry_before = monitor.summary()["topics"]["/inekf/odometry"]["messages"]
            for node in p("kill_nodes", "/semantic_octomap_node /inekf_node").split():
                e2e.kill_node(node)
            player.wait(timeout=10 * duration + 60)
            clock = e2e.ClockAfterBag(bag).__enter__()
            self.addCleanup(clock.__exit__)
            time.sleep(2.0)
        finally:
            stop.set()
            for thread in threads:
                thread.join(timeout=30)
            if player.poll() is None:
                player.kill()
        check_files()
        summary = monitor.summary()

        self.assertEqual(corrupt, [], "a saved map was corrupt at some moment")
        self.assertGreater(saves["ok"], 0, "no save succeeded: %s" % saves)
        clouds_after = summary["topics"]["/semantic_map/labeled_cloud"]["messages"] - clouds_before
        odometry_after = summary["topics"]["/inekf/odometry"]["messages"] - odometry_before
        self.assertGreater(clouds_after, 0, "semantic_octomap_node did not come back")
        self.assertGreater(odometry_after, 0, "inekf_node did not come back")
        # The respawned map node saves again.
        for fmt, path in paths.items():
            response = e2e.save_map(path, fmt, timeout=10.0)
            self.assertTrue(response.success, response.message)
        check_files()
        self.assertEqual(corrupt, [])
        header = e2e.check_ot_file(paths["ot"])
        self.assertGreater(header["size"], 0)
        rospy.loginfo("%s: saves %s, clouds after restart %d, odometry after restart %d",
                      NAME, saves, clouds_after, odometry_after)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", NAME, NodeRestart)
