#!/usr/bin/env python3
"""Adversarial tests of sglc-server: hostile and broken clients against the hardened contract.

Usage: test_adversarial.py SERVER_BINARY PYTHON_STUB_DIR SHARED_DATA_DIR SGLC_CLI [CLASSES]
CLASSES (or the environment variable SGLC_ADV_ONLY) picks probe classes by letter, e.g. "ABE"; default all.

One probe class per file (probe_<letter>_*.py); each starts its own servers on free loopback ports with
temporary databases. Output: one line per probe, "PASS <name>" or "FAIL <name>: expected X, got Y"; notes are
indented; the last line is "N passed, M failed". Exit 1 when a probe failed, 77 when grpcio/numpy are missing.
"""
import importlib
import os
import shutil
import sys
import tempfile
import time
import traceback

try:
    import grpc  # noqa: F401
    import numpy  # noqa: F401
except ImportError as e:
    print(f"SKIP: {e} (needs Debian's python3-grpcio and python3-numpy; run with /usr/bin/python3)")
    sys.exit(77)

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # no __pycache__ in the source tree
sys.path.insert(0, HERE)
import adv_harness as h  # noqa: E402

MODULES = ["probe_a_malformed", "probe_b_transforms", "probe_c_streams", "probe_d_corrupt_stream",
           "probe_e_random_bytes", "probe_f_idempotent", "probe_g_second_server", "probe_h_small",
           "probe_i_auth", "probe_j_memory", "probe_k_crash", "probe_l_sigterm", "probe_m_metrics",
           "probe_n_read_only", "probe_o_files"]

SQL_WORDS = ("INSERT", "SELECT", "UNIQUE constraint", "sqlite")


def no_sql_in_statuses():
    leaks = [(where, code, msg) for where, code, msg in h.STATUSES
             if any(w.lower() in msg.lower() for w in SQL_WORDS)]
    h.note(f"{len(h.STATUSES)} error statuses collected over the suite")
    assert not leaks, (f"expected no SQL in any status message, {len(leaks)} of {len(h.STATUSES)} have some, "
                       f"first: {leaks[0][1]}: '{h.short(leaks[0][2])}'")


def main():
    if len(sys.argv) < 5:
        print(__doc__)
        sys.exit(2)
    h.setup(*sys.argv[1:5])
    only = (sys.argv[5] if len(sys.argv) > 5 else os.environ.get("SGLC_ADV_ONLY", "")).upper()
    print(f"server {h.SERVER}; real scans {'present' if h.HAVE_DATA else 'absent: synthetic scans'}", flush=True)
    t_suite = time.monotonic()
    for name in MODULES:
        if only and name.split("_")[1].upper() not in only:
            continue
        letter = name.split("_")[1].upper()
        tmp = tempfile.mkdtemp(prefix=f"sglc-adv-{letter}-")
        t0 = time.monotonic()
        try:
            mod = importlib.import_module(name)
            print(f"== {letter}: {mod.TITLE}", flush=True)
            mod.run(tmp)
        except Exception as e:  # noqa: BLE001  (a class that could not even set up fails as one probe)
            h.failed += 1
            print(f"FAIL {letter}.setup: {type(e).__name__}: {h.short(str(e), 300)}", flush=True)
            traceback.print_exc(limit=3, file=sys.stdout)
        finally:
            h.end_leftovers()
            shutil.rmtree(tmp, ignore_errors=True)
        h.note(f"class {letter} took {time.monotonic() - t0:.1f} s")
    if not only or "G" in only:
        h.probe("G.no_sql_in_status_messages", no_sql_in_statuses)
    h.note(f"suite took {time.monotonic() - t_suite:.1f} s" + (f"; {h.skipped} skipped" if h.skipped else ""))
    print(f"{h.passed} passed, {h.failed} failed", flush=True)
    sys.exit(1 if h.failed else 0)


if __name__ == "__main__":
    main()
