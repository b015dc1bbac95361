"""scripts/demo.sh on a short drive, against this build: the report's numbers must show the pose graph taking the
drifting odometry's trajectory error and end error down, and the picture and the g2o export must be written.

Usage: test_demo.py REPO_ROOT BUILD_DIR WORK_DIR"""
import os
import re
import shutil
import subprocess
import sys

root, build, work = sys.argv[1:4]
shutil.rmtree(work, ignore_errors=True)
env = dict(os.environ, SGLC_DEMO_SKIP_SETUP="1", SGLC_DEMO_BUILD=build, SGLC_DEMO_FRAMES="0:1911:12",
           SGLC_DEMO_WORK=work)
env.pop("SGLC_SERVER", None)
r = subprocess.run([os.path.join(root, "scripts", "demo.sh")], cwd=root, env=env, capture_output=True, text=True,
                   timeout=540)
print(r.stdout[-3000:], r.stderr[-3000:])
assert r.returncode == 0, f"demo.sh exited {r.returncode}"
phases = re.findall(r"^== \[(\d)/6\]", r.stdout, re.M)
assert phases == [str(i) for i in range(1, 7)], phases
ate = re.search(r"drifting odometry ([0-9.]+) m -> optimised ([0-9.]+) m", r.stdout)
end = re.search(r"error at the end of the drive: drifting odometry ([0-9.]+) m -> optimised ([0-9.]+) m", r.stdout)
assert ate and end, "the report lacks the pose graph's numbers"
assert float(ate.group(2)) < float(ate.group(1)) / 2, ate.group(0)
assert float(end.group(2)) < float(end.group(1)) / 2, end.group(0)
loops = re.search(r"loops: (\d+) intra-robot, (\d+) inter-robot", r.stdout)
assert loops and int(loops.group(2)) > 0, "no inter-robot loop"
assert os.path.getsize(os.path.join(work, "graph", "graph.g2o")) > 0
if shutil.which("python3") and subprocess.run(["/usr/bin/python3", "-c", "import matplotlib"]).returncode == 0:
    assert os.path.getsize(os.path.join(work, "demo.png")) > 10000
print("ok")
