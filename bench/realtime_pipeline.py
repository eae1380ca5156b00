#!/usr/bin/python3
"""Real-time benchmark of the whole pipeline (launch/kitti_bag.launch, no rviz) at rate 1.0.

Measures, while a kitti2bag bag plays: per-node CPU (%, of one core) and memory from /proc,
the wall latency from a scan's arrival to the map update with the same stamp and from an image
to its labels, dropped scans/images, and the real-time factor of each stage (sim time
processed / wall time taken). Prints markdown tables; writes them with the raw figures to
--output-dir. Needs a built workspace (sourced) and a free ROS master port (it starts its own).

  bench/realtime_pipeline.sh [BAG]   # no BAG: a 30 s synthetic drive is generated and converted
"""
import argparse
import json
import os
import subprocess
import sys
import threading
import time
import xmlrpc.client

REPO_ROOT = os.path.realpath(os.path.join(os.path.dirname(os.path.realpath(__file__)), ".."))
sys.path.insert(0, os.path.join(REPO_ROOT, "scripts"))
import compute_demo_metrics as metrics  # noqa: E402
import pipeline_monitor  # noqa: E402

# With nodelets:=true the segmentation and map nodes run in /pipeline_manager (their loaders keep
# the nodes' names and use almost nothing).
NODES = ["/inekf_node", "/segmentation_node", "/semantic_octomap_node", "/pipeline_manager",
         "/rosbag_play"]
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
PLAY_DELAY_S = 5.0  # rosbag play waits this long after advertising, so that all subscribe
PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def node_pid(master, name):
    import rosnode
    try:
        uri = rosnode.get_api_uri(master, name, skip_cache=True)
        if not uri:
            return None
        code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/realtime_bench")
        return pid if code == 1 else None
    except Exception:  # pylint: disable=broad-except
        return None


def cpu_seconds_and_rss(pid):
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    # fields[11], [12] = utime, stime (the 14th/15th of the full line); [21] = rss pages
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS, int(fields[21]) * PAGE_MB


class CpuSampler(threading.Thread):
    def __init__(self, master, period=1.0):
        super().__init__(daemon=True)
        self.master, self.period = master, period
        self.samples = {n: [] for n in NODES}  # (wall, cpu_s, rss_mb)
        self.pids = {}
        self.stop = threading.Event()

    def run(self):
        while not self.stop.is_set():
            now = time.time()
            for name in NODES:
                pid = self.pids.get(name) or node_pid(self.master, name)
                if not pid:
                    continue
                self.pids[name] = pid
                try:
                    cpu, rss = cpu_seconds_and_rss(pid)
                except (OSError, IndexError, ValueError):
                    self.pids.pop(name, None)
                    continue
                self.samples[name].append((now, cpu, rss))
            self.stop.wait(self.period)

    def table(self):
        rows = {}
        for name, samples in self.samples.items():
            if len(samples) < 2:
                continue
            rates = [100.0 * (c1 - c0) / (t1 - t0) for (t0, c0, _), (t1, c1, _) in zip(samples, samples[1:]) if t1 > t0]
            total = 100.0 * (samples[-1][1] - samples[0][1]) / (samples[-1][0] - samples[0][0])
            rows[name] = {"cpu_mean_pct": total, "cpu_max_pct": max(rates), "rss_max_mb": max(s[2] for s in samples)}
        return rows


def stage_realtime_factor(log_stamps, log_arrivals):
    """Sim seconds covered by a stage's outputs per wall second it took to produce them."""
    if len(log_stamps) < 2 or log_arrivals[-1] <= log_arrivals[0]:
        return None
    return (log_stamps[-1] - log_stamps[0]) / (log_arrivals[-1] - log_arrivals[0])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bag", required=True)
    parser.add_argument("--rate", type=float, default=1.0)
    parser.add_argument("--output-dir", required=True)
    parser.add_argument("--model", required=True,
                        help="segmentation model (kitti_bag.launch's model: ENet for real drives, "
                             "models/unet_synthetic.onnx for synthetic ones, none)")
    parser.add_argument("--launch-args", default="", help="extra kitti_bag.launch args (name:=value ...)")
    args = parser.parse_args()
    os.makedirs(args.output_dir, exist_ok=True)
    port = os.environ["ROS_MASTER_URI"].rsplit(":", 1)[1].strip("/")

    launch_log = open(os.path.join(args.output_dir, "launch.log"), "w")
    launch = subprocess.Popen(["roslaunch", "-p", port, "inekf_semantic_mapping", "kitti_bag.launch",
                               "bag:=" + os.path.abspath(args.bag), "model:=" + args.model,
                               "rate:=%g" % args.rate, "rviz:=false",
                               "play_delay:=%g" % PLAY_DELAY_S] + args.launch_args.split(),
                              stdout=launch_log, stderr=subprocess.STDOUT)
    try:
        import rosgraph
        import rospy
        master = rosgraph.Master("/realtime_bench")
        deadline = time.time() + 60
        while not master.is_online():
            if time.time() > deadline:
                raise RuntimeError("no ROS master after 60 s (see %s)" % launch_log.name)
            time.sleep(0.5)
        rospy.init_node("realtime_bench", disable_signals=True)
        monitor = pipeline_monitor.PipelineMonitor()
        sampler = CpuSampler(master)
        sampler.start()
        deadline = time.time() + 60
        while node_pid(master, "/rosbag_play") is None:
            if time.time() > deadline or launch.poll() is not None:
                raise RuntimeError("rosbag_play did not start (see %s)" % launch_log.name)
            time.sleep(0.3)
        play_start = time.time()
        while node_pid(master, "/rosbag_play") is not None:
            time.sleep(0.5)
        play_wall = time.time() - play_start - PLAY_DELAY_S
        time.sleep(3.0)  # the last scans reach the map
        sampler.stop.set()
        summary = monitor.write(args.output_dir)
        logs = {t: (l.stamps, l.arrivals) for t, l in monitor.logs.items()}
    finally:
        launch.send_signal(2)
        try:
            launch.wait(timeout=20)
        except subprocess.TimeoutExpired:
            launch.kill()

    bag_counts, bag_duration = metrics.bag_message_counts(args.bag)
    messages = metrics.rates_and_drops(summary, bag_counts)
    cpu = sampler.table()
    n = lambda topic: summary["topics"].get(topic, {}).get("messages", 0)
    stages = [
        ("lidar scans -> semantic map", "/kitti/velo/pointcloud", "/semantic_map/labeled_cloud"),
        ("camera images -> labels", "/kitti/camera_color_left/image_raw", "/segmentation/labels"),
        ("IMU -> odometry", "/kitti/oxts/imu", "/inekf/odometry"),
    ]
    lines = ["| node | CPU mean % (1 core = 100) | CPU max % | RSS max MB |", "|---|---:|---:|---:|"]
    for name in NODES:
        row = cpu.get(name)
        if row:
            lines.append("| %s | %.0f | %.0f | %.0f |" % (name.lstrip("/"), row["cpu_mean_pct"], row["cpu_max_pct"], row["rss_max_mb"]))
    lines.append("| all of them | %.0f | | %.0f |" % (sum(r["cpu_mean_pct"] for r in cpu.values()),
                                                   sum(r["rss_max_mb"] for r in cpu.values())))
    lines += ["", "| stage | in bag | received | output | dropped | output rate Hz | stage real-time factor |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for label, source, sink in stages:
        rtf = stage_realtime_factor(*logs[sink])
        rate = summary["topics"].get(sink, {}).get("rate_hz")
        lines.append("| %s | %d | %d | %d | %d | %s | %s |" % (
            label, bag_counts.get(source, 0), n(source), n(sink), bag_counts.get(source, 0) - n(sink),
            "%.1f" % rate if rate else "-", "%.2f" % rtf if rtf else "-"))
    lines += ["", "| latency (wall, s) | matched | mean | p50 | p95 | max |", "|---|---:|---:|---:|---:|---:|"]
    for label, key in (("scan arrival -> map update", "scan_to_map_latency_s"),
                       ("image arrival -> labels", "image_to_labels_latency_s")):
        lat = summary.get(key)
        if lat:
            lines.append("| %s | %d | %.3f | %.3f | %.3f | %.3f |" % (label, lat["matched"], lat["mean"], lat["p50"], lat["p95"], lat["max"]))
        else:
            lines.append("| %s | 0 | - | - | - | - |" % label)
    lines += ["", "bag %.1f s played in %.1f s wall at rate %g (real-time factor of playback %.2f); %d CPU cores."
              % (bag_duration, play_wall, args.rate, bag_duration / play_wall if play_wall else 0, os.cpu_count())]
    table = "\n".join(lines)
    print(table)
    with open(os.path.join(args.output_dir, "realtime.md"), "w") as f:
        f.write(table + "\n")
    with open(os.path.join(args.output_dir, "realtime.json"), "w") as f:
        json.dump({"cpu": cpu, "messages": messages, "play_wall_s": play_wall, "bag_duration_s": bag_duration},
                  f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
