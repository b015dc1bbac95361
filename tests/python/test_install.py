"""`pip install ./client/python` offline into a fresh venv on Debian's python3 (with its grpcio, protobuf and
numpy), then the installed package is used from outside the source tree."""
import os
import subprocess
import sys
import venv

import pytest

from conftest import BUILD, REPO


def test_pip_install_offline(tmp_path):
    if not os.path.isfile(os.path.join(BUILD, "CMakeCache.txt")):
        pytest.skip(f"{BUILD} is not a configured build tree")
    env_dir = tmp_path / "venv"
    try:
        venv.EnvBuilder(system_site_packages=True, with_pip=True).create(env_dir)
    except Exception as e:  # noqa: BLE001 - ensurepip missing (python3-venv not installed)
        pytest.fail(f"cannot create a venv with pip (scripts/install-deps.sh installs python3-venv): {e}")
    py = str(env_dir / "bin" / "python")
    env = dict(os.environ, SGLC_BUILD_DIR=BUILD, PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
    env.pop("PYTHONPATH", None)
    pip = subprocess.run([py, "-m", "pip", "install", "--no-index", os.path.join(REPO, "client", "python")],
                         capture_output=True, text=True, env=env, timeout=1800)
    assert pip.returncode == 0, pip.stdout[-2000:] + pip.stderr[-2000:]
    code = ("import sglc, sys; assert 'site-packages' in sglc.__file__, sglc.__file__; "
            "import sglc.v1.sglc_pb2 as pb; c = sglc.Client('127.0.0.1:1'); "
            "print(sglc.__version__, pb.DESCRIPTOR.package, type(c).__name__)")
    run = subprocess.run([py, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert run.returncode == 0, run.stderr
    version, package, name = run.stdout.split()
    assert package == "sglc.v1" and name == "Client"
    with open(os.path.join(REPO, "CMakeLists.txt")) as f:
        assert f"VERSION {version} " in f.read()  # the project's version
    engine_built = any(n.startswith("_engine.") for n in os.listdir(os.path.join(BUILD, "python", "sglc")))
    if engine_built:
        run = subprocess.run([py, "-c", "import sglc, numpy as np; f = sglc.Engine().fingerprint(np.zeros((9, 3)));"
                              "print(f.num_points)"], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
        assert run.returncode == 0 and run.stdout.strip() == "9", run.stderr
