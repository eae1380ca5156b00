#!/usr/bin/python3
"""Tests of scripts/count_test_results.py, which makes ./scripts/test.sh's closing line: each
test case counted once (catkin_test_results counted a gtest case twice), skips as skips (a
Python test node's loud skips read as passes), a rostest's wrapper case only when it failed, and
an unreadable file as a failure; and of env.sh's JUnit writer, whose messages are escaped (a file
that did not parse was dropped from the counts). Runs standalone or under
test/ros/count_test_results.test."""
import os
import subprocess
import sys
import tempfile
import unittest

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
COUNTER = os.path.join(REPO_ROOT, "scripts", "count_test_results.py")

GTEST = """<?xml version="1.0" encoding="UTF-8"?>
<testsuites tests="3" failures="1" disabled="0" errors="0" name="AllTests">
  <testsuite name="A" tests="3" failures="1" skipped="1" errors="0">
    <testcase name="passes" status="run" result="completed" classname="A"/>
    <testcase name="fails" status="run" result="completed" classname="A">
      <failure message="x"/>
    </testcase>
    <testcase name="skips" status="run" result="skipped" classname="A">
      <skipped message="shared data not found"/>
    </testcase>
  </testsuite>
</testsuites>
"""
ROSUNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuite errors="0" failures="0" name="unittest.suite.TestSuite" tests="3" time="0.0">
<testcase classname="__main__.T" name="test_a" time="0.1" />
<testcase classname="__main__.T" name="test_b" time="0.1" />
<testcase classname="__main__.T" name="test_c" time="0.1" />
<system-err>&lt;![CDATA[
*** SKIPPED: ../shared not found
]]&gt;</system-err></testsuite>
"""
WRAPPER_PASSED = """<?xml version="1.0" encoding="utf-8"?>
<testsuite errors="0" failures="0" name="unittest.suite.TestSuite" tests="1" time="1.0">
<testcase classname="rostest.runner.RosTest" name="testnode" time="1.0" /></testsuite>
"""
WRAPPER_FAILED = """<?xml version="1.0" encoding="utf-8"?>
<testsuite errors="1" failures="0" name="unittest.suite.TestSuite" tests="1" time="1.0">
<testcase classname="rostest.runner.RosTest" name="testother" time="1.0">
<error type="" message="test [other] did not generate test results" /></testcase></testsuite>
"""


def count(folder):
    result = subprocess.run(["/usr/bin/python3", COUNTER, folder, "--list-failed"],
                            capture_output=True, text=True, check=True)
    return tuple(int(n) for n in result.stdout.split()), result.stderr


class CountTestResults(unittest.TestCase):
    def write(self, folder, name, text):
        with open(os.path.join(folder, name), "w") as f:
            f.write(text)

    def test_each_case_once_skips_as_skips_and_wrappers_only_when_they_failed(self):
        with tempfile.TemporaryDirectory() as tmp:
            package = os.path.join(tmp, "inekf_semantic_mapping")
            os.makedirs(package)
            self.write(package, "gtest-a.xml", GTEST)
            self.write(package, "rosunit-node.xml", ROSUNIT)
            self.write(package, "rostest-test_ros_node.xml", WRAPPER_PASSED)
            self.write(package, "rostest-test_ros_other.xml", WRAPPER_FAILED)
            (passed, failed, skipped), listing = count(tmp)
            # gtest: 1 passed, 1 failed, 1 skipped; rosunit: 3 cases, one loud skip; the passing
            # wrapper nothing, the failed one a failure.
            self.assertEqual((passed, failed, skipped), (1 + 2, 1 + 1, 1 + 1))
            self.assertIn("gtest-a.xml: A.fails", listing)
            self.assertIn("rostest-test_ros_other.xml", listing)

    def test_a_file_that_does_not_parse_is_a_failure(self):
        with tempfile.TemporaryDirectory() as tmp:
            self.write(tmp, "gtest-broken.xml", GTEST[:200])
            (passed, failed, skipped), listing = count(tmp)
            self.assertEqual((passed, failed, skipped), (0, 1, 0))
            self.assertIn("unreadable result file", listing)

    def test_the_junit_writer_escapes_what_it_is_given(self):
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "x.xml")
            subprocess.run(["bash", "-c", 'source "$0"/scripts/env.sh >/dev/null; '
                            'ism_junit_failure "$1" "suite<1>" "case & co" "said \\"no\\" <here>"',
                            REPO_ROOT, path], check=True)
            (passed, failed, skipped), listing = count(tmp)
            self.assertEqual((passed, failed, skipped), (0, 1, 0))
            self.assertIn("suite<1>.case & co", listing)


if __name__ == "__main__":
    if any(a.startswith("__name:=") for a in sys.argv) or "--gtest_output" in " ".join(sys.argv):
        import rostest

        rostest.rosrun("inekf_semantic_mapping", "count_test_results", CountTestResults)
    else:
        unittest.main()
