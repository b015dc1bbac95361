#!/usr/bin/env python3
"""The dependency map of docs/ARCHITECTURE.md, checked on every #include of every module.

Each module may include only the project headers of the modules below it, and only the external libraries it
is allowed to depend on: a header that is neither the C++ standard library, a known POSIX header, a project
header nor one of the named libraries is itself a violation, as is a relative include that leaves its
directory. Prints every violation (file:line and the rule) and exits 1 if there is any.
"""
import os
import re
import sys

ROOT = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", ".."))

TYPES_HEADERS = {"sglc/types.hpp", "sglc/rigid.hpp", "sglc/deskew.hpp", "sglc/names.hpp", "sglc/elapsed.hpp", "sglc/params.hpp",
                 "sglc/version.hpp"}  # version.hpp: generated from core/include/sglc/version.hpp.in
ENGINE_HEADERS = {"sglc/" + f for f in os.listdir(os.path.join(ROOT, "core/include/sglc"))} - TYPES_HEADERS
IO_HEADERS = {"sglc/" + f for f in os.listdir(os.path.join(ROOT, "io/include/sglc"))}
TYPES_FILES = [f"core/{d}/{n}" for d, ext in (("include/sglc", "hpp"), ("src", "cpp"))
               for n in (f"types.{ext}", f"rigid.{ext}", f"deskew.{ext}", f"names.{ext}", f"params.{ext}")]

# Project headers by the module that provides them.
def provider(header):
    if header in TYPES_HEADERS:
        return "types"
    if header in ENGINE_HEADERS:
        return "core"
    if header in IO_HEADERS:
        return "io"
    for prefix, module in (("sglc/storage/", "storage"), ("sglc/closing/", "closing"), ("sglc/posegraph/", "posegraph"),
                           ("sglc/log/", "log"), ("sglc/config/", "config"), ("sglc/wire/", "wire"), ("sglc/v1/", "proto"),
                           ("sglc/client/", "client"), ("sim/", "sim")):
        if header.startswith(prefix):
            return module
    return None

# External libraries, by include prefix.
EXTERNAL = {"Eigen/": "eigen", "yaml-cpp/": "yaml", "zlib.h": "zlib", "grpcpp/": "grpc", "grpc++/": "grpc",
            "grpc/": "grpc", "absl/": "grpc", "google/protobuf/": "protobuf", "sqlite3.h": "sqlite",
            "faiss/": "faiss", "omp.h": "openmp", "cblas.h": "blas", "spdlog/": "spdlog", "ceres/": "ceres",
            "nlohmann/": "json", "CLI/": "cli11", "benchmark/": "benchmark", "gtest/": "gtest", "gmock/": "gtest",
            "pybind11/": "pybind11", "pqxx/": "postgres", "libpq-fe.h": "postgres", "pcl/": "pcl",
            "zstd.h": "zstd", "lz4frame.h": "lz4", "bzlib.h": "bzip2", "boost/asio/": "beast", "boost/beast/": "beast"}
# Operating-system headers any module may use (the C++ standard headers have no ".h" and no "/").
POSIX = {"unistd.h", "fcntl.h", "signal.h", "malloc.h", "errno.h", "arpa/inet.h", "netinet/in.h", "poll.h",
         "sys/file.h", "sys/resource.h", "sys/socket.h", "sys/wait.h", "sys/stat.h", "sys/types.h", "sys/mman.h",
         "sys/time.h", "time.h", "dirent.h", "pthread.h", "netdb.h", "spawn.h", "endian.h", "dlfcn.h"}

# module: (source directories, project modules it may include, external libraries it may use)
ALL = {"types", "core", "config", "io", "storage", "closing", "posegraph", "log", "proto", "wire", "client", "sim"}
LAYERS = {
    "types": (TYPES_FILES, {"types"}, {"eigen"}),
    "core": (["core/src", "core/include"], {"types", "core"}, {"eigen", "zlib"}),
    # Settings files: the registries of sglc/params.hpp in YAML, and the engine's configuration file.
    "config": (["config"], {"types", "core", "config"}, {"yaml"}),
    # Point-cloud files: PCD and PLY through PCL's I/O module (in io/src/pcl_cloud.cpp only). Bags: MCAP chunks
    # through zstd and lz4 with zlib's CRC-32, rosbag2 .db3 through SQLite, metadata.yaml through yaml-cpp.
    "io": (["io"], {"types", "io"}, {"eigen", "pcl", "zstd", "lz4", "bzip2", "zlib", "sqlite", "yaml"}),
    # The map database: SQLite (embedded) or PostgreSQL through libpq, the FAISS indexes.
    "storage": (["storage"], {"types", "core", "storage"}, {"eigen", "sqlite", "postgres", "faiss"}),
    # The use cases: the engine and the map database, nothing of any transport.
    "closing": (["closing"], {"types", "core", "storage", "closing"}, {"eigen"}),
    # One JSON object per log line.
    "log": (["log"], {"log"}, {"json", "spdlog"}),
    # Each map's pose graph: the map database's graph tables and Ceres.
    "posegraph": (["posegraph"], {"types", "storage", "log", "posegraph", "io"}, {"eigen", "ceres", "spdlog", "json"}),
    "wire": (["proto/include", "proto/src"], {"types", "proto", "wire"}, {"eigen", "grpc", "protobuf"}),
    # json: the loop exports (export_formats.cpp) that the command line and other C++ clients share.
    "client": (["client/include", "client/src"], {"types", "proto", "wire", "client"}, {"eigen", "grpc", "protobuf", "json"}),
    "server": (["server/src"], {"types", "core", "config", "storage", "closing", "posegraph", "log", "proto", "wire"},
               {"eigen", "grpc", "protobuf", "spdlog", "json", "cli11", "beast"}),
    # The command line is a client: it reads files, it does not run the engine or open the database.
    "cli": (["client/cli"], {"types", "io", "proto", "wire", "client"}, {"eigen", "grpc", "protobuf", "json", "cli11"}),
    # The Python package's engine module (sglc._engine): the engine and its YAML configuration, and the scan and
    # bag readers, through pybind11.
    "python": (["client/python/engine"], {"types", "core", "config", "io"}, {"eigen", "pybind11"}),
    "tools": (["tools"], ALL, {"eigen", "grpc", "protobuf", "json", "cli11", "benchmark", "spdlog", "yaml"}),
}

INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]')


def sources(paths):
    for p in paths:
        full = os.path.join(ROOT, p)
        if os.path.isfile(full):
            yield full
            continue
        for dirpath, _, names in os.walk(full):
            for n in sorted(names):
                if n.endswith((".cpp", ".hpp", ".h")):
                    yield os.path.join(dirpath, n)


def main():
    problems, checked = [], 0
    claimed = {os.path.join(ROOT, f) for f in TYPES_FILES}
    for module, (paths, allowed, external) in LAYERS.items():
        for path in sources(paths):
            if module != "types" and path in claimed:
                continue  # the types sources sit in core/src but belong to the types layer
            checked += 1
            own_dir = os.path.dirname(path)
            for line_no, line in enumerate(open(path, encoding="utf-8"), 1):
                m = INCLUDE.match(line)
                if not m:
                    continue
                header = m.group(1)
                where = f"{os.path.relpath(path, ROOT)}:{line_no}"
                if header.startswith("..") or "/../" in header:
                    problems.append(f"{where}: {module} includes {header}, outside its own directory")
                    continue
                if os.path.exists(os.path.join(own_dir, header)) and provider(header) is None:
                    continue  # a private header beside it
                if module == "tools" and provider(header) is None and '"' in line:
                    continue  # tools' own headers and the server's private ones (benchmarks)
                owner = provider(header)
                if owner is not None:
                    if owner not in allowed:
                        problems.append(f"{where}: {module} includes {header} ({owner}), not in {sorted(allowed)}")
                    continue
                lib = next((v for k, v in EXTERNAL.items() if header.startswith(k)), None)
                if lib is None:
                    if header in POSIX or ("/" not in header and "." not in header):
                        continue  # the operating system, the C++ standard library
                    problems.append(f"{where}: {module} includes {header}, which the map does not know")
                elif lib not in external:
                    problems.append(f"{where}: {module} includes {header} ({lib}), not in {sorted(external)}")
    for p in problems:
        print(p)
    print(f"{checked} files checked, {len(problems)} include(s) against the dependency map")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
