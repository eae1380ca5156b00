#!/usr/bin/python3
"""Counts the test cases in a folder of JUnit XML results: prints "PASSED FAILED SKIPPED".

catkin_test_results' totals are not used for the closing line: they add a gtest file's
<testsuites> root to its suites (every case counted twice), count a skipped gtest case once as
run and once as skipped, and count each rostest's wrapper case (rostest-*.xml) beside the cases of
its test node (rosunit-*.xml). Here every <testcase> counts once:
  * failed: it holds a <failure> or <error>;
  * skipped: gtest's <skipped> (or result="skipped"); a Python test node's skips are not
    recorded by rosunit (they read as passed), so each "*** SKIPPED" line in a rosunit file's
    system-err (test/ros tests print one for each skip) turns one of its passed cases into a
    skipped one;
  * a rostest-*.xml wrapper case counts only when it failed (the test node did not run or gave no
    results); its passing case is the node's cases, counted in their own file;
  * a file that does not parse is one failed case (catkin_test_results skipped it silently).

usage: count_test_results.py RESULTS_DIR [--list-failed]
"""
import os
import sys
import xml.etree.ElementTree as ElementTree


def count_file(path):
    """(passed, failed, skipped, failed names) of one result file."""
    name = os.path.basename(path)
    try:
        root = ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError) as error:
        return 0, 1, 0, [f"{name}: unreadable result file ({error})"]
    passed = failed = skipped = 0
    failed_names = []
    wrapper = name.startswith("rostest-")
    for case in root.iter("testcase"):
        case_name = f"{name}: {case.get('classname', '')}.{case.get('name', '')}"
        if case.find("failure") is not None or case.find("error") is not None:
            failed += 1
            failed_names.append(case_name)
        elif wrapper:
            continue
        elif case.find("skipped") is not None or case.get("result") == "skipped":
            skipped += 1
        else:
            passed += 1
    if name.startswith("rosunit-"):
        loud_skips = sum((element.text or "").count("*** SKIPPED")
                         for element in root.iter("system-err"))
        moved = min(loud_skips, passed)
        passed -= moved
        skipped += moved
    return passed, failed, skipped, failed_names


def count_folder(folder):
    totals = [0, 0, 0]
    failed_names = []
    for directory, _, files in sorted(os.walk(folder)):
        for file_name in sorted(files):
            if not file_name.endswith(".xml"):
                continue
            passed, failed, skipped, names = count_file(os.path.join(directory, file_name))
            totals[0] += passed
            totals[1] += failed
            totals[2] += skipped
            failed_names += names
    return totals, failed_names


def main(argv):
    if len(argv) < 2 or not os.path.isdir(argv[1]):
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    (passed, failed, skipped), failed_names = count_folder(argv[1])
    if "--list-failed" in argv:
        for name in failed_names:
            print(f"FAILED {name}", file=sys.stderr)
    print(passed, failed, skipped)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
