// Fuzzing the scan-file readers of sglc/scan_file.hpp beyond KITTI .bin: NumPy .npy (points and labels), PCD
// (ascii, binary, binary_compressed) and PLY (ascii, binary), on mutated files. Every failure must be an
// InputError (never a crash: PCL's own readers crash on some headers, which sglc_io checks first); what is
// accepted must have finite points and one label per point, or none.
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>
#include <fstream>

#include "fuzz_util.hpp"
#include "sglc/npy.hpp"
#include "sglc/pcl_cloud.hpp"
#include "sglc/scan_file.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using fuzz::Outcome;
using fuzz::Rng;

const char* const kExtensions[] = {".npy", ".pcd", ".ply"};

struct CloudCase {
  std::uint8_t format = 0;  // index into kExtensions
  bool npy_labels = false;  // .npy only: read as a label file next to seed points
  std::string data;
};

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void writeFile(const std::string& path, const std::string& data) {
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(data.data(), static_cast<std::streamsize>(data.size()));
}

// Seeds: files written by our writers and by PCL for a small labelled scan.
std::vector<std::string> seedsOf(int format, bool labels, const test::TempDir& dir) {
  const LabelledScan scan{{Vec3f(1.5f, -2.25f, 0.125f), Vec3f(10, 20, -1.7f), Vec3f(-40, 3, 2)}, {40, 50, 10}};
  std::vector<std::string> out;
  const std::string f = dir.file(std::string("seed") + kExtensions[format]);
  if (format == 0) {
    labels ? writeNpyLabels(f, scan.labels) : writeNpyPoints(f, scan.points);
    out.push_back(readFile(f));
  } else if (format == 1) {
    for (const bool binary : {false, true}) {
      writePcd(f, scan, binary);
      out.push_back(readFile(f));
    }
    pcl::PointCloud<pcl::PointXYZL> cloud;
    for (std::size_t i = 0; i < scan.points.size(); ++i) {
      pcl::PointXYZL p;
      p.x = scan.points[i].x(), p.y = scan.points[i].y(), p.z = scan.points[i].z(), p.label = scan.labels[i];
      cloud.push_back(p);
    }
    pcl::io::savePCDFileBinaryCompressed(f, cloud);
    out.push_back(readFile(f));
  } else {
    out.push_back(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "property uint label\nend_header\n1.5 -2.25 0.125 40\n10 20 -1.7 50\n-40 3 2 10\n");
    std::string bin =
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nproperty uint label\nend_header\n";
    for (std::size_t i = 0; i < 3; ++i) {
      bin.append(reinterpret_cast<const char*>(scan.points[i].data()), 12);
      bin.append(reinterpret_cast<const char*>(&scan.labels[i]), 4);
    }
    out.push_back(bin);
  }
  return out;
}

TEST(Fuzz, CloudFormats) {
  const test::TempDir dir;
  std::vector<std::string> corpora[4];  // npy points, pcd, ply, npy labels
  for (int f = 0; f < 3; ++f) corpora[f] = seedsOf(f, false, dir);
  corpora[3] = seedsOf(0, true, dir);
  std::vector<std::string> all;
  for (const auto& c : corpora) all.insert(all.end(), c.begin(), c.end());
  const fuzz::Mutator mutator({"\x93NUMPY",
                               "'descr'",
                               "'<f4'",
                               "'<u4'",
                               "'|O'",
                               "'shape'",
                               "(",
                               ")",
                               ", ",
                               "True",
                               "False",
                               "99999999999",
                               "-1",
                               "FIELDS",
                               "SIZE",
                               "TYPE",
                               "COUNT",
                               "WIDTH",
                               "HEIGHT",
                               "POINTS",
                               "DATA",
                               "ascii",
                               "binary",
                               "binary_compressed",
                               " x y z label",
                               " 4 4 4 4",
                               " F F F U",
                               " 1 1 1 1",
                               "element vertex ",
                               "property float x\n",
                               "property list uchar int x\n",
                               "end_header\n",
                               "format ascii 1.0\n",
                               "format binary_little_endian 1.0\n",
                               "nan",
                               "\n",
                               "4294967296",
                               "\xff\xff\xff\xff"});
  std::vector<CloudCase> seeds;
  for (std::uint8_t f = 0; f < 3; ++f)
    for (const auto& s : corpora[f]) seeds.push_back({f, false, s});
  for (const auto& s : corpora[3]) seeds.push_back({0, true, s});
  const std::string seed_points = dir.file("points.npy");
  writeFile(seed_points, corpora[0][0]);

  auto make = [&](Rng& rng, std::uint64_t i) -> CloudCase {
    if (i < seeds.size()) return seeds[i];
    CloudCase c;
    const auto k = fuzz::below(rng, 4);
    c.format = static_cast<std::uint8_t>(k == 3 ? 0 : k);
    c.npy_labels = k == 3;
    if (fuzz::chance(rng, 5)) {
      c.data = mutator.random(rng, 2048);
    } else {
      c.data = corpora[k][fuzz::below(rng, corpora[k].size())];
      mutator.mutate(rng, c.data, all, 4096);
    }
    return c;
  };
  auto check = [&](const CloudCase& c, fuzz::Verdict& v) -> Outcome {
    const std::string file = dir.file(std::string(c.npy_labels ? "labels" : "case") + kExtensions[c.format]);
    writeFile(file, c.data);
    try {
      const LabelledScan s = c.npy_labels ? readScan(seed_points, file) : readScan(file, "");
      if (!s.labels.empty() && s.labels.size() != s.points.size()) v.fail("label and point counts differ");
      for (const auto& p : s.points)
        if (!p.allFinite()) {
          v.fail("a non-finite point was accepted");
          break;
        }
    } catch (const InputError& e) {
      if (!*e.what()) v.fail("InputError with an empty message");
      return Outcome::kRejected;
    }
    return Outcome::kAccepted;
  };
  auto bytes = [](const CloudCase& c) { return std::string(1, char(c.format)) + char(c.npy_labels) + c.data; };
  auto describe = [](const CloudCase& c) {
    return std::string(c.npy_labels ? "npy labels" : kExtensions[c.format]) + " " + fuzz::hexPreview(c.data);
  };
  const auto r = fuzz::runFuzz<CloudCase>("CloudFormats", 20000, seeds.size(), make, check, bytes, describe);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, seeds.size()) << "the valid seeds must be read";
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
