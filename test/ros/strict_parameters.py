"""Starts a node binary with one misspelt private parameter and returns its exit code and output.

Every node reads its private parameters through the strict reader (ros/node_parameters.h): an
unknown name must stop the node with a message naming the parameter and the node, and the
message must reach the terminal (roscpp shuts rosconsole down with a node's last NodeHandle, so a
fatal message printed after that is lost).
"""
import subprocess

import roslib.packages

PACKAGE = "inekf_semantic_mapping"


def run_with_parameters(executable, node_name, parameters, timeout_s=60):
    """Runs `executable` as node `node_name` with `parameters` ({name: value} set as _name:=value)
    and returns (exit code, stdout + stderr)."""
    path = roslib.packages.find_node(PACKAGE, executable)[0]
    args = [path, "__name:=" + node_name]
    args += ["_%s:=%s" % (name, value) for name, value in parameters.items()]
    result = subprocess.run(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            timeout=timeout_s)
    return result.returncode, result.stdout
