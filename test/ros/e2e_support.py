"""Shared pieces of the end-to-end and robustness rostests (test/ros/e2e_*.py, robustness_*.py).

The robot_localization bag-replay pattern: the .test file starts the nodes with use_sim_time;
the test node makes its data (a short synthetic drive -> kitti2bag bag, cached per binary
version so several tests in one run share it), plays the bag with `rosbag play --clock`, records
what the nodes publish and asserts on it. The metric functions are the demo's
(scripts/compute_demo_metrics.py), so a test and the demo compute the same figures.
"""
import glob
import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time

import rospy

REPO_ROOT = os.path.realpath(os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", ".."))
sys.path.insert(0, os.path.join(REPO_ROOT, "scripts"))
import compute_demo_metrics as metrics  # noqa: E402  (the demo's metric functions)
import pipeline_monitor  # noqa: E402

PACKAGE = "inekf_semantic_mapping"
CACHE_ROOT = os.environ.get("ISM_E2E_CACHE", "/tmp/ism_e2e_cache")


def shared_dir():
    return os.environ.get("ISM_SHARED_DIR") or os.path.join(REPO_ROOT, "..", "shared")


def find_executable(name):
    """A package executable (catkin devel space), or None."""
    import roslib.packages
    try:
        paths = roslib.packages.find_node(PACKAGE, name)
    except Exception:  # pylint: disable=broad-except
        paths = []
    return paths[0] if paths else None


def skip_loudly(test_case, message):
    """Skips the test and says so where a reader of the log looks: rosunit records a Python
    test's skip as a pass, so the "*** SKIPPED" line on stderr is what the closing count
    (scripts/count_test_results.py) and a reader go by."""
    message = "SKIPPED: " + message
    sys.stderr.write("\n*** %s ***\n" % message)
    sys.stderr.flush()
    rospy.logwarn(message)
    test_case.skipTest(message)


def require_executables(test_case, *names):
    missing = [n for n in names if find_executable(n) is None]
    if missing:
        test_case.fail("executables not built: %s (build them: scripts/build.sh all)" % ", ".join(missing))
    return [find_executable(n) for n in names]


def run_logged(command, log_path, timeout):
    """Runs a command, its output to log_path; raises with the log's tail on failure."""
    with open(log_path, "w") as log:
        result = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, timeout=timeout)
    if result.returncode != 0:
        with open(log_path) as log:
            tail = log.read()[-3000:]
        raise RuntimeError("%s exited %d:\n%s" % (" ".join(command), result.returncode, tail))


def _file_digest(path):
    """Content hash of a binary: a relink that changes nothing keeps the cached data."""
    digest = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _cache_key(*parts):
    digest = hashlib.sha1()
    for part in parts:
        digest.update(repr(part).encode())
    return digest.hexdigest()[:16]


def synthetic_drive(duration_s, seed=7, generator_args=()):
    """Generates (once per generator version) a synthetic drive; returns its _sync folder."""
    generator = find_executable("generate_synthetic_drive")
    if generator is None:
        raise RuntimeError("generate_synthetic_drive is not built")
    key = _cache_key("drive", duration_s, seed, tuple(generator_args), _file_digest(generator))
    out_dir = os.path.join(CACHE_ROOT, "drive_" + key)
    done = os.path.join(out_dir, ".complete")
    if not os.path.exists(done):
        shutil.rmtree(out_dir, ignore_errors=True)
        os.makedirs(out_dir)
        started = time.time()
        run_logged([generator, "--output", out_dir, "--seed", str(seed), "--duration", str(duration_s)]
                   + list(generator_args), os.path.join(out_dir, "generate.log"), timeout=300)
        rospy.loginfo("synthetic drive %.0f s generated in %.1f s", duration_s, time.time() - started)
        open(done, "w").close()
    drives = sorted(glob.glob(os.path.join(out_dir, "*", "*_drive_*_sync")))
    if not drives:
        raise RuntimeError("generate_synthetic_drive wrote no <date>/<date>_drive_NNNN_sync in " + out_dir)
    return drives[0]


# GPS as in the evaluation protocol: 1.5 m / 3 m noise at 1 Hz, fixed seed.
PROTOCOL_BAG_ARGS = "--gps-sigma-h 1.5 --gps-sigma-v 3 --gps-every 10 --seed 1"


def param(name, default):
    """A private parameter of the test node (set by the .test file), else `default`."""
    return rospy.get_param("~" + name, default)


def synthetic_bag_from_params(default_duration=12.0, default_seed=7):
    """The drive and bag a test asks for with ~duration, ~seed, ~generator_args and ~bag_args.

    Returns (duration_s, drive_dir, bag_path)."""
    duration = param("duration", default_duration)
    drive = synthetic_drive(duration, seed=param("seed", default_seed),
                            generator_args=param("generator_args", "").split())
    bag = kitti2bag(drive, param("bag_args", PROTOCOL_BAG_ARGS).split())
    return duration, drive, bag


def ground_truth_dir(drive_dir):
    """The synthetic drive's ground_truth/ folder (beside or inside the drive), or None."""
    for candidate in (os.path.join(drive_dir, "ground_truth"),
                      os.path.join(os.path.dirname(drive_dir), "ground_truth"),
                      os.path.join(os.path.dirname(os.path.dirname(drive_dir)), "ground_truth")):
        if os.path.isdir(candidate):
            return candidate
    return None


def kitti2bag(drive_dir, bag_args=()):
    """Converts a drive into a bag (cached by drive, options and kitti2bag version)."""
    converter = find_executable("kitti2bag")
    if converter is None:
        raise RuntimeError("kitti2bag is not built")
    key = _cache_key("bag", os.path.realpath(drive_dir), tuple(bag_args), _file_digest(converter),
                     os.path.getmtime(drive_dir))
    os.makedirs(CACHE_ROOT, exist_ok=True)
    bag = os.path.join(CACHE_ROOT, "bag_%s.bag" % key)
    if not os.path.exists(bag):
        tmp = bag + ".partial.bag"
        run_logged([converter, "--drive", drive_dir, "--output", tmp] + list(bag_args),
                   bag + ".log", timeout=300)
        os.replace(tmp, bag)
    return bag


def stop_process(process, log_file=None, timeout=20):
    """Stops a roslaunch (or any child) the way Ctrl-C does, killing it if it hangs, then closes
    its log file."""
    if process.poll() is None:
        process.send_signal(2)  # SIGINT: roslaunch shuts its nodes down
        try:
            process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    if log_file is not None and not log_file.closed:
        log_file.close()


# rosbag play waits 0.2 s after advertising its topics; the subscribers connect after that (one
# XML-RPC round and one TCP connection each), and on a loaded machine the first message of every
# topic was lost before the test's own monitor had connected. Two seconds covers that.
CONNECT_DELAY_S = 2.0


def _play_command(bag, rate, extra_args):
    extra_args = list(extra_args)
    if not any(a.startswith("--delay") or a == "-d" for a in extra_args):
        extra_args.append("--delay=%g" % CONNECT_DELAY_S)
    return ["rosbag", "play", "--clock", "--quiet", "--rate=%g" % rate] + extra_args + [bag]


def play_bag(bag, rate=1.0, extra_args=(), timeout=300):
    """Plays a bag with /clock (after the connection delay) and waits for the end."""
    subprocess.run(_play_command(bag, rate, extra_args), stdout=subprocess.DEVNULL,
                   stderr=subprocess.STDOUT, timeout=timeout, check=True)


class ClockAfterBag:
    """Publishes /clock onward from the bag's end at wall rate while active (context manager).

    With use_sim_time, a node waiting for tf with a timeout waits on ROS time; once the bag has
    ended /clock stops and such a wait never returns (blocking that node's services). A live
    system's time goes on: this gives a replayed one the same property (scripts/clock_after_bag.py
    does it for the demo)."""

    def __init__(self, bag):
        import rosbag
        with rosbag.Bag(bag) as b:
            self.start = b.get_end_time()
        self.stop = None

    def __enter__(self):
        import threading
        from rosgraph_msgs.msg import Clock
        publisher = rospy.Publisher("/clock", Clock, queue_size=1)
        self.stop = threading.Event()
        wall_start = time.time()

        def run():
            while not self.stop.is_set():
                publisher.publish(Clock(clock=rospy.Time.from_sec(self.start + time.time() - wall_start)))
                time.sleep(0.02)
        self.thread = threading.Thread(target=run, daemon=True)
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(timeout=2)
        return False


def start_bag(bag, rate=1.0, extra_args=()):
    """Starts playing a bag with /clock (after the connection delay); returns the process."""
    return subprocess.Popen(_play_command(bag, rate, extra_args), stdout=subprocess.DEVNULL,
                            stderr=subprocess.STDOUT)


def wait_for_subscribers(topics, timeout=30.0):
    """Waits (wall time) until every topic has a subscriber, so that no message is lost."""
    import rosgraph
    master = rosgraph.Master("/e2e_test")
    deadline = time.time() + timeout
    while time.time() < deadline:
        _, subscribers, _ = master.getSystemState()
        subscribed = {topic for topic, nodes in subscribers if nodes}
        if all(t in subscribed for t in topics):
            return True
        time.sleep(0.2)
    return False


class DiagnosticsRecorder:
    """Records /diagnostics while it lives: per status name the worst level, the fewest key/values
    and the last message (0 OK, 1 WARN, 2 ERROR, 3 STALE)."""

    def __init__(self):
        from diagnostic_msgs.msg import DiagnosticArray
        import threading
        self._lock = threading.Lock()
        self._statuses = {}
        self._subscriber = rospy.Subscriber("/diagnostics", DiagnosticArray, self._on_array,
                                            queue_size=100)

    def _on_array(self, array):
        with self._lock:
            for status in array.status:
                if status.message == "Node starting up":
                    continue  # diagnostic_updater's placeholder when a task is added
                entry = self._statuses.setdefault(status.name, {
                    "max_level": 0, "min_values": len(status.values), "messages": 0})
                entry["max_level"] = max(entry["max_level"], ord(status.level)
                                         if isinstance(status.level, bytes) else status.level)
                entry["min_values"] = min(entry["min_values"], len(status.values))
                entry["messages"] += 1
                entry["last_message"] = status.message
                if entry["max_level"] >= 2 and "error_message" not in entry:
                    entry["error_message"] = status.message

    def summary(self):
        with self._lock:
            return {name: dict(entry) for name, entry in self._statuses.items()}


def wait_until(predicate, timeout, period=0.2):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if predicate():
            return True
        time.sleep(period)
    return predicate()


def save_map(path, fmt, service="/semantic_octomap_node/save_map", timeout=20.0):
    """Calls ~save_map; returns the response."""
    from inekf_semantic_mapping.srv import SaveMap
    rospy.wait_for_service(service, timeout=timeout)
    return rospy.ServiceProxy(service, SaveMap)(path=path, format=fmt)


def check_ot_file(path):
    """Raises unless path is a complete octomap .ot file (header and data size consistent)."""
    with open(path, "rb") as f:
        first = f.readline()
        if not first.startswith(b"# Octomap OcTree file"):
            raise ValueError("%s: not an octomap .ot file (first line %r)" % (path, first[:40]))
        fields = {}
        while True:
            line = f.readline()
            if not line:
                raise ValueError("%s: .ot header has no 'data' line" % path)
            line = line.strip()
            if line == b"data":
                break
            if line.startswith(b"#") or not line:
                continue
            key, _, value = line.partition(b" ")
            fields[key.decode()] = value.decode()
        for required in ("id", "size", "res"):
            if required not in fields:
                raise ValueError("%s: .ot header lacks '%s'" % (path, required))
        payload = f.read()
    if int(fields["size"]) > 0 and len(payload) == 0:
        raise ValueError("%s: .ot file has a header but no node data" % path)
    return {"id": fields["id"], "size": int(fields["size"]), "res": float(fields["res"]),
            "data_bytes": len(payload)}


def kill_node(node_name, sig=signal.SIGKILL):
    """Kills a node's process by the pid it reports over XML-RPC (no name matching)."""
    import rosnode
    import xmlrpc.client
    uri = rosnode.get_api_uri(rosgraph_master(), node_name, skip_cache=True)
    if not uri:
        raise RuntimeError("node %s is not running" % node_name)
    code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/e2e_test")
    if code != 1:
        raise RuntimeError("getPid failed for " + node_name)
    os.kill(pid, sig)
    return pid


def rosgraph_master():
    import rosgraph
    return rosgraph.Master("/e2e_test")
