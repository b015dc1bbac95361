"""The PEP 517 build backend of the sglc Python package (in-tree, standard library only, so that
`pip install ./client/python` works offline: pip has nothing to download to build it).

build_wheel builds the CMake target sglc_python in the project's build directory (SGLC_BUILD_DIR, default
<repository>/build; configured with Ninja/Release if it has no CMakeCache.txt), which assembles the package in
<build dir>/python/sglc: the Python sources, the stubs generated from proto/sglc/v1/sglc.proto and the engine
module sglc._engine. It then writes that directory into a wheel. The wheel is tagged for this interpreter
when it holds the engine module, which must have been built for this interpreter's ABI.
"""
import base64
import hashlib
import importlib.machinery
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
PACKAGE_DIR = os.path.dirname(HERE)  # client/python


class BuildError(RuntimeError):
    pass


def _source_dir():
    root = os.environ.get("SGLC_SOURCE_DIR") or os.path.normpath(os.path.join(PACKAGE_DIR, "..", ".."))
    if not os.path.isfile(os.path.join(root, "proto", "sglc", "v1", "sglc.proto")):
        raise BuildError(f"sglc: {root} is not the SGLC repository (no proto/sglc/v1/sglc.proto); build from the "
                         "repository, or set SGLC_SOURCE_DIR")
    return root


def _run(cmd):
    print("sglc build:", " ".join(cmd), file=sys.stderr, flush=True)
    done = subprocess.run(cmd, stdout=sys.stderr, stderr=sys.stderr)
    if done.returncode != 0:
        raise BuildError(f"sglc: `{' '.join(cmd)}` failed (exit {done.returncode}); see the output above")


def _build_package():
    """Builds the target sglc_python; returns <build dir>/python/sglc."""
    root = _source_dir()
    build = os.path.abspath(os.environ.get("SGLC_BUILD_DIR") or os.path.join(root, "build"))
    cmake = shutil.which("cmake")
    if cmake is None:
        raise BuildError("sglc: cmake not found (run scripts/install-deps.sh as root first)")
    if not os.path.isfile(os.path.join(build, "CMakeCache.txt")):
        cmd = [cmake, "-S", root, "-B", build, "-DCMAKE_BUILD_TYPE=Release",
               f"-DPython3_EXECUTABLE={os.path.realpath(sys.executable)}"]
        if shutil.which("ninja"):
            cmd += ["-G", "Ninja"]
        _run(cmd)
    _run([cmake, "--build", build, "--target", "sglc_python"])
    package = os.path.join(build, "python", "sglc")
    for needed in ("__init__.py", "version.py", os.path.join("v1", "sglc_pb2.py"), os.path.join("v1", "sglc_pb2_grpc.py")):
        if not os.path.isfile(os.path.join(package, needed)):
            raise BuildError(f"sglc: the build did not produce {os.path.join(package, needed)}")
    return package


def _package_files(package):
    """(path on disk, path in the wheel) of every file of the package, sorted (reproducible wheels)."""
    out = []
    for dirpath, dirnames, filenames in os.walk(package):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for name in sorted(filenames):
            if name.endswith((".pyc", ".pyo")):
                continue
            full = os.path.join(dirpath, name)
            out.append((full, "sglc/" + os.path.relpath(full, package).replace(os.sep, "/")))
    return out


def _engine_module(files):
    modules = [arc for _, arc in files if re.fullmatch(r"sglc/_engine\..+\.so", arc)]
    if not modules:
        return None
    suffix = modules[0][len("sglc/_engine"):]
    if suffix not in importlib.machinery.EXTENSION_SUFFIXES:
        raise BuildError(f"sglc: the engine module {modules[0]} was built for another Python than {sys.executable} "
                         f"(which loads {importlib.machinery.EXTENSION_SUFFIXES[0]}); rebuild with "
                         f"-DPython3_EXECUTABLE={os.path.realpath(sys.executable)} or another SGLC_BUILD_DIR")
    return modules[0]


def _tag(has_engine):
    if not has_engine:
        return "py3-none-any"
    py = f"cp{sys.version_info.major}{sys.version_info.minor}"
    platform = re.sub(r"[-.]", "_", sysconfig.get_platform())
    return f"{py}-{py}-{platform}"


def _version(package):
    text = open(os.path.join(package, "version.py"), encoding="utf-8").read()
    m = re.search(r'__version__\s*=\s*"([^"]+)"', text)
    if not m:
        raise BuildError(f"sglc: no __version__ in {package}/version.py")
    return m.group(1)


def _metadata(version):
    with open(os.path.join(PACKAGE_DIR, "pyproject.toml"), "rb") as f:
        project = tomllib.load(f)["project"]
    lines = ["Metadata-Version: 2.1", f"Name: {project['name']}", f"Version: {version}",
             f"Summary: {project['description']}", f"Requires-Python: {project['requires-python']}",
             f"License: {project['license']['text']}"]
    lines += [f"Requires-Dist: {d}" for d in project.get("dependencies", [])]
    readme = os.path.join(PACKAGE_DIR, project.get("readme", "README.md"))
    body = open(readme, encoding="utf-8").read() if os.path.isfile(readme) else ""
    return "\n".join(lines) + "\nDescription-Content-Type: text/markdown\n\n" + body


def _record_line(arcname, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{arcname},sha256={digest},{len(data)}"


def _write_wheel(wheel_directory, package):
    files = _package_files(package)
    has_engine = _engine_module(files) is not None
    version, tag = _version(package), _tag(has_engine)
    name = f"sglc-{version}-{tag}.whl"
    info = f"sglc-{version}.dist-info"
    generated = {
        f"{info}/METADATA": _metadata(version).encode(),
        f"{info}/WHEEL": (f"Wheel-Version: 1.0\nGenerator: sglc_build\nRoot-Is-Purelib: {str(not has_engine).lower()}\n"
                          f"Tag: {tag}\n").encode(),
        f"{info}/top_level.txt": b"sglc\n",
    }
    record = []
    path = os.path.join(wheel_directory, name)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for full, arc in files:
            with open(full, "rb") as f:
                data = f.read()
            z.writestr(zipfile.ZipInfo(arc, date_time=(1980, 1, 1, 0, 0, 0)), data, zipfile.ZIP_DEFLATED)
            record.append(_record_line(arc, data))
        for arc, data in generated.items():
            z.writestr(zipfile.ZipInfo(arc, date_time=(1980, 1, 1, 0, 0, 0)), data, zipfile.ZIP_DEFLATED)
            record.append(_record_line(arc, data))
        record.append(f"{info}/RECORD,,")
        z.writestr(zipfile.ZipInfo(f"{info}/RECORD", date_time=(1980, 1, 1, 0, 0, 0)), "\n".join(record) + "\n")
    return name


# ----------------------------------------------------------------------------------------------------------
# PEP 517 hooks

def get_requires_for_build_wheel(config_settings=None):
    return []


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    return _write_wheel(wheel_directory, _build_package())


def build_sdist(sdist_directory, config_settings=None):
    raise BuildError("sglc: no source distribution; the package is built from the SGLC repository "
                     "(pip install ./client/python)")
