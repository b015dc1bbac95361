"""Checks of the deployment files in deploy/ that run without Docker or root.

Usage: test_deploy.py REPO_ROOT BIN_DIR

- .dockerignore keeps host build trees out of the image's build context;
- compose.yaml parses, builds from the Dockerfile that exists, and probes health with grpc.health.v1;
- the Dockerfile's COPY sources exist, and its runtime stage installs every Debian package that provides a
  shared library of sglc-server or sglc (ldd + dpkg -S; skipped where dpkg is missing);
- the systemd unit's install steps create the user and /etc/sglc, and its ExecStart line, pointed at this
  build and a temporary directory, starts a server that answers SERVING and stops cleanly on SIGTERM;
- the Kubernetes manifests parse, probe the gRPC port with grpc.health, take the database password from a
  secret (as PGPASSWORD, never in the URL on the command line), and their server configuration is accepted by
  this build's sglc-server (--dump-config), which prints a URL's password as ***;
- the nginx configuration passes `nginx -t` (skipped where nginx is missing) and balances over grpc_pass.
"""
import os
import re
import shutil
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import time

import yaml

ROOT, BIN = sys.argv[1], sys.argv[2]
DEPLOY = os.path.join(ROOT, "deploy")


def read(path):
    with open(path) as f:
        return f.read()


def test_dockerignore():
    ignored = {l.strip() for l in read(os.path.join(ROOT, ".dockerignore")).splitlines() if l and l[0] != "#"}
    for needed in (".git", "build", "build-*", "var"):
        assert needed in ignored, f".dockerignore lacks {needed}"


def test_compose():
    doc = yaml.safe_load(read(os.path.join(DEPLOY, "compose.yaml")))
    svc = doc["services"]["sglc"]
    context = os.path.normpath(os.path.join(DEPLOY, svc["build"]["context"]))
    assert os.path.isfile(os.path.join(context, svc["build"]["dockerfile"])), "compose builds a missing Dockerfile"
    test = svc["healthcheck"]["test"]
    assert test[0] == "CMD" and test[1].endswith("/sglc") and test[2] == "health", test


def runtime_packages(dockerfile):
    """The packages the last stage's apt-get install line names."""
    last_stage = dockerfile[dockerfile.rindex("\nFROM "):]
    install = re.search(r"apt-get install -y --no-install-recommends(.*?)(&&|$)", last_stage.replace("\\\n", " "),
                        re.S)
    return set(install.group(1).split())


def package_of(lib):
    for path in {lib, os.path.realpath(lib), "/usr" + lib, "/usr" + os.path.realpath(lib)}:
        r = subprocess.run(["dpkg", "-S", path], capture_output=True, text=True)
        if r.returncode == 0:
            return r.stdout.split(":")[0]
    return None


def closure(packages):
    r = subprocess.run(["apt-cache", "depends", "--recurse", "--no-recommends", "--no-suggests", "--no-conflicts",
                        "--no-breaks", "--no-replaces", "--no-enhances", *packages], capture_output=True, text=True)
    out = set(packages)
    for line in r.stdout.splitlines():
        line = line.strip()
        if line.startswith(("Depends:", "PreDepends:")):
            out.add(line.split(":", 1)[1].strip().strip("<>").split(":")[0])
        elif line and not line.startswith(("|", " ")) and ":" not in line:
            out.add(line.split(":")[0])
    return out


def test_dockerfile():
    text = read(os.path.join(DEPLOY, "Dockerfile"))
    for src in re.findall(r"^COPY (?!--from)(\S+) ", text, re.M):
        assert os.path.exists(os.path.join(ROOT, src)), f"Dockerfile copies missing {src}"
    if subprocess.run(["which", "dpkg"], capture_output=True).returncode != 0:
        print("  dpkg missing: runtime package check skipped")
        return
    listed = runtime_packages(text)
    # What debian:12-slim brings (apt and its dependencies) plus what the listed packages pull in.
    have = closure(sorted(listed | {"apt", "base-files"}))
    needed = {}
    for binary in ("sglc-server", "sglc"):
        ldd = subprocess.run(["ldd", os.path.join(BIN, binary)], capture_output=True, text=True, check=True).stdout
        if "libasan" in ldd:
            # The sanitizer build's sglc needs more of PCL's libraries (Qt, octree) than the Release one;
            # the image holds a Release build, which the Release run checks.
            print("  sanitizer build: runtime package check skipped")
            return
        for lib in re.findall(r"=> (/\S+)", ldd):
            pkg = package_of(lib)
            if pkg:
                needed.setdefault(pkg, set()).add(f"{binary}: {os.path.basename(lib)}")
    missing = {p: sorted(w) for p, w in needed.items() if p not in have}
    assert not missing, f"runtime stage lacks packages for {missing}"
    print(f"  runtime stage: {len(listed)} packages listed cover {len(needed)} packages of shared libraries")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_systemd_unit():
    unit = read(os.path.join(DEPLOY, "sglc-server.service"))
    assert re.search(r"useradd --system .* sglc", unit), "install steps must create the sglc user"
    assert "install -d -m 755 /etc/sglc" in unit, "install steps must create /etc/sglc"
    exec_start = re.search(r"^ExecStart=(.*)$", unit, re.M).group(1)
    with tempfile.TemporaryDirectory() as tmp:
        state = os.path.join(tmp, "var-lib-sglc")
        os.makedirs(state)
        port = free_port()
        line = (exec_start.replace("/usr/local/bin/", BIN + "/")
                .replace("/etc/sglc/sglc.yaml", os.path.join(DEPLOY, "sglc.yaml"))
                .replace("/var/lib/sglc", state))
        argv = shlex.split(line) + ["--listen", f"127.0.0.1:{port}"]
        proc = subprocess.Popen(argv, cwd=state, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            health = [os.path.join(BIN, "sglc"), "health", "--server", f"127.0.0.1:{port}", "--timeout", "5"]
            deadline = time.monotonic() + 120  # generous: a loaded CI machine
            while True:
                r = subprocess.run(health, capture_output=True, text=True)
                if r.returncode == 0 and "SERVING" in r.stdout:
                    break
                assert proc.poll() is None, f"ExecStart exited {proc.returncode}: {proc.stdout.read()}"
                assert time.monotonic() < deadline, f"never SERVING: {r.stdout} {r.stderr}"
                time.sleep(0.2)
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=120) == 0, proc.stdout.read()
        finally:
            if proc.poll() is None:
                proc.kill()
        assert os.path.isfile(os.path.join(state, "map.db")), "the database goes where the unit says"


def test_kubernetes():
    k8s = os.path.join(DEPLOY, "k8s")
    docs = {}
    for name in sorted(os.listdir(k8s)):
        if name.endswith(".yaml"):
            for doc in yaml.safe_load_all(read(os.path.join(k8s, name))):
                if doc:
                    docs[(doc["kind"], doc["metadata"]["name"])] = doc
    deployment = docs[("Deployment", "sglc-server")]
    container = deployment["spec"]["template"]["spec"]["containers"][0]
    port = next(p["containerPort"] for p in container["ports"] if p["name"] == "grpc")
    for probe in ("readinessProbe", "livenessProbe"):
        assert container[probe]["grpc"]["port"] == port, f"{probe} must use grpc.health on the gRPC port"
    env = {e["name"]: e for e in container["env"]}
    password = env["PGPASSWORD"]["valueFrom"]["secretKeyRef"]
    assert ("Secret", password["name"]) in docs
    assert password["key"] in docs[("Secret", password["name"])]["stringData"]
    url = container["args"][container["args"].index("--db") + 1]
    assert url.startswith("postgresql://") and ":" not in url.split("//")[1].split("@")[0], \
        "the URL on the command line carries no password"
    service = docs[("Service", "sglc")]
    assert service["spec"]["selector"] == deployment["spec"]["selector"]["matchLabels"]
    config = docs[("ConfigMap", "sglc-config")]["data"]["sglc.yaml"]
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "sglc.yaml")
        with open(path, "w") as f:
            f.write(config.replace("/etc/sglc/secrets/tokens", os.devnull))
        out = subprocess.run([os.path.join(BIN, "sglc-server"), "--config", path, "--dump-config"],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, f"sglc-server refuses the ConfigMap's configuration: {out.stderr}"
        assert yaml.safe_load(out.stdout)["server"]["listen"] == f"0.0.0.0:{port}"
        out = subprocess.run([os.path.join(BIN, "sglc-server"), "--config", path, "--db",
                              "postgresql://sglc:s3cret@db:5432/sglc?sslmode=require", "--dump-config"],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0 and "s3cret" not in out.stdout, "--dump-config printed the password"
        assert yaml.safe_load(out.stdout)["server"]["db"] == "postgresql://sglc:***@db:5432/sglc?sslmode=require"


def test_nginx():
    conf = read(os.path.join(DEPLOY, "nginx", "sglc-grpc.conf"))
    assert "grpc_pass grpc://sglc_replicas" in conf and "http2" in conf
    deletes = conf[conf.index("MapAdmin/(DeleteSession|DeleteRobot|DeleteMap|Backup)"):]
    deletes = deletes[:deletes.index("}")]
    assert "non_idempotent" not in deletes, "deletes and backups must not be resent to another replica"
    nginx = shutil.which("nginx") or ("/usr/sbin/nginx" if os.path.exists("/usr/sbin/nginx") else None)
    if not nginx:
        print("skip nginx -t: nginx is not installed (scripts/install-deps.sh installs it)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        conf = re.sub(r"^pid .*$", f"pid {tmp}/nginx.pid;", conf, flags=re.M)
        conf = re.sub(r"^error_log .*$", f"error_log {tmp}/error.log;", conf, flags=re.M)
        conf = conf.replace("http {", f"http {{\n  client_body_temp_path {tmp}/body;\n  proxy_temp_path {tmp}/p;\n"
                            f"  fastcgi_temp_path {tmp}/f;\n  uwsgi_temp_path {tmp}/u;\n  scgi_temp_path {tmp}/s;", 1)
        path = os.path.join(tmp, "nginx.conf")
        with open(path, "w") as f:
            f.write(conf)
        out = subprocess.run([nginx, "-t", "-c", path, "-p", tmp], capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, f"nginx -t: {out.stderr}"


def main():
    failed = 0
    for t in (test_dockerignore, test_compose, test_dockerfile, test_systemd_unit, test_kubernetes, test_nginx):
        try:
            t()
            print(f"ok   {t.__name__}")
        except Exception as e:  # report every check, then fail
            failed += 1
            print(f"FAIL {t.__name__}: {e!r}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
