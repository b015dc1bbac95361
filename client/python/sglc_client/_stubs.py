"""Finds and imports the generated sglc.v1 Python stubs (sglc_pb2, sglc_pb2_grpc).

The stubs are generated at build time into <build dir>/python/sglc/v1/. They are looked up, in order:

1. the ``stubs_path`` given to :func:`load_stubs` (or to ``Client(..., stubs_path=...)``),
2. the directory in the environment variable ``SGLC_PYTHON_STUBS``,
3. ``build/python`` of the source tree this package sits in (``client/python/sglc_client`` -> ``build/python``),
4. whatever ``import sglc.v1.sglc_pb2`` finds on ``sys.path`` already.

Each directory named must contain ``sglc/v1/sglc_pb2.py``. The first successful load is kept for the
life of the process (protobuf registers the messages once); later stubs_path arguments are then ignored.
"""
import importlib
import os
import sys

ENV_VAR = "SGLC_PYTHON_STUBS"

_loaded = None  # (sglc_pb2, sglc_pb2_grpc, directory or None)


def _candidates(stubs_path):
    if stubs_path:
        yield os.fspath(stubs_path), True
    env = os.environ.get(ENV_VAR)
    if env:
        yield env, True
    here = os.path.dirname(os.path.abspath(__file__))
    yield os.path.normpath(os.path.join(here, "..", "..", "..", "build", "python")), False


def _has_stubs(directory):
    return os.path.isfile(os.path.join(directory, "sglc", "v1", "sglc_pb2.py"))


def load_stubs(stubs_path=None):
    """Returns (sglc_pb2, sglc_pb2_grpc), importing them on first use. Raises ImportError saying where it looked."""
    global _loaded
    if _loaded is not None:
        return _loaded[0], _loaded[1]
    looked = []
    chosen = None
    for directory, explicit in _candidates(stubs_path):
        if _has_stubs(directory):
            chosen = directory
            break
        looked.append(directory)
        if explicit:
            # A path the user named must be right: do not silently fall back to another build.
            raise ImportError(
                f"no sglc/v1/sglc_pb2.py under {directory} (from "
                f"{'stubs_path' if stubs_path else ENV_VAR}); build the project to generate the Python stubs")
    if chosen is not None and chosen not in sys.path:
        sys.path.insert(0, chosen)
    try:
        pb2 = importlib.import_module("sglc.v1.sglc_pb2")
        pb2_grpc = importlib.import_module("sglc.v1.sglc_pb2_grpc")
    except ImportError as e:
        raise ImportError(
            "cannot import the generated sglc.v1 stubs (looked in " + ", ".join(looked or ["sys.path"]) +
            f"); build the project, then set {ENV_VAR}=<build dir>/python or pass stubs_path: {e}") from e
    _loaded = (pb2, pb2_grpc, chosen)
    return pb2, pb2_grpc
