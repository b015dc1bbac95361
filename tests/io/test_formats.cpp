// Scan files in every supported format: NumPy .npy, PCD (ascii, binary, binary_compressed), PLY, KITTI .bin,
// and the extension dispatch of readScan.
#include <gtest/gtest.h>

#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>
#include <bit>
#include <cstring>
#include <fstream>

#include "io_files.hpp"
#include "sglc/io.hpp"
#include "sglc/npy.hpp"
#include "sglc/pcl_cloud.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::errorOf;
using test::npy;
using test::TempDir;
using test::writeBytes;

template <typename T>
std::string bytesOf(std::initializer_list<T> values, bool big_endian = false) {
  std::string s;
  for (T v : values) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (big_endian) std::reverse(b, b + sizeof(T));
    s.append(b, sizeof(T));
  }
  return s;
}

Points samplePoints() { return {Vec3f(1.5f, -2.25f, 0.125f), Vec3f(-3, 4, 5), Vec3f(100.5f, 0, -1.75f)}; }

TEST(Npy, WrittenFilesReadBack) {
  TempDir dir;
  const Points pts = samplePoints();
  const std::vector<std::uint32_t> labels{10, 40, 4294967295u};
  writeNpyPoints(dir.file("p.npy"), pts);
  writeNpyLabels(dir.file("l.npy"), labels);
  EXPECT_EQ(readNpyPoints(dir.file("p.npy")), pts);
  EXPECT_EQ(readNpyLabels(dir.file("l.npy")), labels);
  const LabelledScan scan = readScan(dir.file("p.npy"), dir.file("l.npy"));
  EXPECT_EQ(scan.points, pts);
  EXPECT_EQ(scan.labels, labels);
}

TEST(Npy, Float64KittiColumnsFortranOrderAndBigEndian) {
  TempDir dir;
  // (2, 4) float64 in C order: x y z r per row; the reflectance column is ignored.
  writeBytes(dir.file("c.npy"), npy("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 4), }",
                                    bytesOf<double>({1, 2, 3, 0.5, 4, 5, 6, 0.25})));
  EXPECT_EQ(readNpyPoints(dir.file("c.npy")), (Points{Vec3f(1, 2, 3), Vec3f(4, 5, 6)}));
  // The same points in Fortran (column-major) order.
  writeBytes(dir.file("f.npy"),
             npy("{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }", bytesOf<double>({1, 4, 2, 5, 3, 6})));
  EXPECT_EQ(readNpyPoints(dir.file("f.npy")), (Points{Vec3f(1, 2, 3), Vec3f(4, 5, 6)}));
  writeBytes(dir.file("b.npy"),
             npy("{'descr': '>f4', 'fortran_order': False, 'shape': (1, 3), }", bytesOf<float>({7, 8, 9}, true)));
  EXPECT_EQ(readNpyPoints(dir.file("b.npy")), (Points{Vec3f(7, 8, 9)}));
}

TEST(Npy, AnyIntegerLabelType) {
  TempDir dir;
  writeBytes(dir.file("u1.npy"), npy("{'descr': '|u1', 'fortran_order': False, 'shape': (3,), }", "\x01\x02\xff"));
  EXPECT_EQ(readNpyLabels(dir.file("u1.npy")), (std::vector<std::uint32_t>{1, 2, 255}));
  writeBytes(dir.file("i8.npy"), npy("{'descr': '<i8', 'fortran_order': False, 'shape': (2, 1), }",
                                     bytesOf<std::int64_t>({40, 4294967295LL})));
  EXPECT_EQ(readNpyLabels(dir.file("i8.npy")), (std::vector<std::uint32_t>{40, 4294967295u}));
  writeBytes(dir.file("i2.npy"),
             npy("{'descr': '>i2', 'fortran_order': False, 'shape': (1,), }", bytesOf<std::int16_t>({300}, true)));
  EXPECT_EQ(readNpyLabels(dir.file("i2.npy")), (std::vector<std::uint32_t>{300}));
}

TEST(Npy, BadFilesAreRefusedWithTheReason) {
  TempDir dir;
  const std::string f = dir.file("bad.npy");
  auto expect = [&](const std::string& bytes, const std::string& reason, bool labels = false) {
    writeBytes(f, bytes);
    const std::string msg = errorOf([&] { labels ? (void)readNpyLabels(f) : (void)readNpyPoints(f); });
    EXPECT_NE(msg.find(reason), std::string::npos) << msg;
    EXPECT_NE(msg.find(f), std::string::npos) << msg;
  };
  expect("not numpy at all", "no \\x93NUMPY magic");
  expect(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }", bytesOf<float>({1, 2, 3})),
         "declares 6 elements");
  expect(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2), }", bytesOf<float>({1, 2})), "(N, 3)");
  expect(npy("{'descr': '<i4', 'fortran_order': False, 'shape': (1, 3), }", bytesOf<std::int32_t>({1, 2, 3})),
         "float32 or float64");
  expect(npy("{'descr': [('x', '<f4'), ('y', '<f4')], 'fortran_order': False, 'shape': (1,), }", "12345678"),
         "structured");
  expect(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 3), }", bytesOf<float>({1, NAN, 3})), "non-finite");
  expect(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999999999999, 3), }", ""), "too large");
  expect(npy("{'descr': '<f4', 'shape': (1, 3), }", bytesOf<float>({1, 2, 3})), "'fortran_order'");
  expect(std::string("\x93NUMPY\x01\x00\xff\x7f{'descr'", 17), "truncated");
  expect(npy("{'descr': '<i4', 'fortran_order': False, 'shape': (1,), }", bytesOf<std::int32_t>({-1})), "negative",
         true);
  expect(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (1,), }", bytesOf<float>({1})), "integers", true);
  expect(npy("{'descr': '<u4', 'fortran_order': False, 'shape': (1, 2), }", bytesOf<std::uint32_t>({1, 2})), "(N,)",
         true);
}

TEST(PclCloud, PcdInEveryEncodingCarriesItsLabels) {
  TempDir dir;
  LabelledScan scan{samplePoints(), {10, 252, 81}};
  for (const bool binary : {false, true}) {
    const std::string f = dir.file(binary ? "b.pcd" : "a.pcd");
    writePcd(f, scan, binary);
    const LabelledScan back = readScan(f, "");
    EXPECT_EQ(back.points, scan.points);
    EXPECT_EQ(back.labels, scan.labels);
  }
  // binary_compressed, written by PCL itself as PointXYZRGBL.
  pcl::PointCloud<pcl::PointXYZRGBL> cloud;
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    pcl::PointXYZRGBL p;
    p.x = scan.points[i].x(), p.y = scan.points[i].y(), p.z = scan.points[i].z();
    p.label = scan.labels[i];
    cloud.push_back(p);
  }
  ASSERT_EQ(pcl::io::savePCDFileBinaryCompressed(dir.file("c.pcd"), cloud), 0);
  const LabelledScan back = readScan(dir.file("c.pcd"), "");
  EXPECT_EQ(back.points, scan.points);
  EXPECT_EQ(back.labels, scan.labels);
  // A label file given on top replaces the embedded labels; a named field is read instead of "label".
  writeLabels(dir.file("x.label"), {1, 2, 3});
  EXPECT_EQ(readScan(dir.file("c.pcd"), dir.file("x.label")).labels, (std::vector<std::uint32_t>{1, 2, 3}));
  EXPECT_TRUE(readScan(dir.file("c.pcd"), "", "semantic").labels.empty());
}

TEST(PclCloud, PlyWithANamedLabelFieldAndWithout) {
  TempDir dir;
  writeBytes(dir.file("s.ply"),
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\n"
             "property ushort semantic\nend_header\n1 2 3 40\n-4 5.5 6 48\n");
  const LabelledScan s = readScan(dir.file("s.ply"), "", "semantic");
  EXPECT_EQ(s.points, (Points{Vec3f(1, 2, 3), Vec3f(-4, 5.5f, 6)}));
  EXPECT_EQ(s.labels, (std::vector<std::uint32_t>{40, 48}));
  EXPECT_TRUE(readScan(dir.file("s.ply"), "").labels.empty());  // no "label" field: unlabelled
}

TEST(PclCloud, BrokenFilesAreRefusedWithTheReason) {
  TempDir dir;
  writeBytes(dir.file("nan.pcd"),
             "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
             "HEIGHT 1\nPOINTS 1\nDATA ascii\nnan 1 2\n");
  EXPECT_NE(errorOf([&] { readScan(dir.file("nan.pcd"), ""); }).find("non-finite"), std::string::npos);
  writeBytes(dir.file("noz.pcd"),
             "VERSION .7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\n"
             "HEIGHT 1\nPOINTS 1\nDATA ascii\n0 1\n");
  EXPECT_NE(errorOf([&] { readScan(dir.file("noz.pcd"), ""); }).find("no 'z' field (fields: x y)"), std::string::npos);
  writeBytes(dir.file("junk.pcd"), "this is not a point cloud");
  EXPECT_NE(errorOf([&] { readScan(dir.file("junk.pcd"), ""); }).find("not a PCD file"), std::string::npos);
  // Headers that crash PCL 1.13's own readers are refused before PCL sees them.
  const std::pair<std::string, std::string> bad_ply[] = {
      {"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nend_header\n1\n", "too few for 5 vertices"},
      {"ply\nformat ascii 1.0\nelement vertex -3\nproperty float x\nend_header\n", "not a non-negative integer"},
      {"ply\nformat ascii 1.0\nelement vertex 2\nproperty list uchar int x\nend_header\n3 1 2 3\n1 1\n",
       "only scalar properties"},
      {"ply\nformat binary_little_endian 1.0\nelement vertex 1000000\nproperty float x\nproperty float y\n"
       "property float z\nend_header\nabc",
       "too few for 1000000 vertices"},
      {"junk\nend_header\n", "first line is not 'ply'"},
      {"junk", "no 'end_header' line"},
  };
  for (const auto& [text, reason] : bad_ply) {
    writeBytes(dir.file("bad.ply"), text);
    const std::string msg = errorOf([&] { readScan(dir.file("bad.ply"), ""); });
    EXPECT_NE(msg.find(reason), std::string::npos) << msg;
  }
  // Files that make PCL 1.13 write past its buffer, abort, or return a wrong cloud (an adversarial review).
  const std::string head =
      "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
      "POINTS 2\n";
  const std::pair<std::string, std::string> bad_pcd[] = {
      {head + "DATA ascii\nCOUNT 1 1 100000\n1 2 3\n", "holds a 'COUNT' header line"},
      {head + "DATA binary\n" + std::string("COUNT 1 1 99999999\n\0\0\0\0\0", 24), "holds a 'COUNT' header line"},
      {head + "DATA ascii\n1 2 3\n4 5\n", "has 2 values, the header declares 3"},
      {head + "DATA ascii\n1 2 3\n4 5 six\n", "'six' is not a number"},
      {head + "DATA ascii\n1 2 3\n", "1 lines for POINTS 2"},
  };
  for (const auto& [text, reason] : bad_pcd) {
    writeBytes(dir.file("bad.pcd"), text);
    const std::string msg = errorOf([&] { readScan(dir.file("bad.pcd"), ""); });
    EXPECT_NE(msg.find(reason), std::string::npos) << msg;
  }
  const std::string xyz = "property float x\nproperty float y\nproperty float z\n";
  const std::pair<std::string, std::string> bad_ply2[] = {
      {"ply\nformat ascii 1.0\nobj_info num_cols 1\nobj_info num_rows 1\nelement vertex 2\n" + xyz +
           "end_header\n0 0 0\n1 1 1\n",
       "organised PLY"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty uchar blue\n" + xyz + "end_header\n1 2 3 4\n",
       "colour property 'blue'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\n" + xyz +
           "element camera 1\nproperty int viewportx\nend_header\n1 2 3\n0\n",
       "element 'camera' is not supported"},
      {"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nelement vertex 1\n" + xyz +
           "end_header\n1 2 3\n",
       "vertex element must come first"},
  };
  for (const auto& [text, reason] : bad_ply2) {
    writeBytes(dir.file("bad.ply"), text);
    const std::string msg = errorOf([&] { readScan(dir.file("bad.ply"), ""); });
    EXPECT_NE(msg.find(reason), std::string::npos) << msg;
  }
  // Full red, green, blue in order is fine.
  writeBytes(dir.file("rgb.ply"), "ply\nformat ascii 1.0\nelement vertex 1\n" + xyz +
                                      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                                      "end_header\n1 2 3 10 20 30\n");
  EXPECT_EQ(readScan(dir.file("rgb.ply"), "").points, (Points{Vec3f(1, 2, 3)}));
  writeBytes(dir.file("nofields.pcd"), "VERSION .7\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n");
  EXPECT_NE(errorOf([&] { readScan(dir.file("nofields.pcd"), ""); }).find("no FIELDS line"), std::string::npos);
  writeBytes(dir.file("neg.pcd"),
             "VERSION .7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F I\nCOUNT 1 1 1 1\n"
             "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n0 1 2 -5\n");
  EXPECT_NE(errorOf([&] { readScan(dir.file("neg.pcd"), ""); }).find("not an integer"), std::string::npos);
  EXPECT_NE(errorOf([&] { readScan(dir.file("missing.pcd"), ""); }).find("cannot open"), std::string::npos);
}

TEST(ScanFile, UnknownExtensionsNameTheSupportedFormats) {
  TempDir dir;
  writeBytes(dir.file("s.xyz"), "1 2 3\n");
  const std::string msg = errorOf([&] { readScan(dir.file("s.xyz"), ""); });
  EXPECT_NE(msg.find("unsupported format: '.xyz'"), std::string::npos) << msg;
  EXPECT_NE(msg.find(".pcd"), std::string::npos) << msg;
  writeNpyPoints(dir.file("p.npy"), samplePoints());
  writeBytes(dir.file("l.txt"), "1\n2\n3\n");
  EXPECT_NE(errorOf([&] { readScan(dir.file("p.npy"), dir.file("l.txt")); }).find("unsupported format: '.txt'"),
            std::string::npos);
  writeNpyLabels(dir.file("two.npy"), {1, 2});
  EXPECT_NE(errorOf([&] { readScan(dir.file("p.npy"), dir.file("two.npy")); }).find("2 labels for 3 points"),
            std::string::npos);
}

// The real KITTI loop scan, converted to every format, reads back to the same points and labels.
TEST(ScanFile, RealScanIsTheSameInEveryFormat) {
  SGLC_REQUIRE_REAL_DATA();
  const std::string dir = test::scansDir() + "/sequences/00";
  const LabelledScan bin = readScan(dir + "/velodyne/000052.bin", dir + "/labels/000052.label");
  TempDir tmp;
  writeNpyPoints(tmp.file("s.npy"), bin.points);
  writeNpyLabels(tmp.file("s_labels.npy"), bin.labels);
  writePcd(tmp.file("s.pcd"), bin, true);
  const LabelledScan npy_scan = readScan(tmp.file("s.npy"), tmp.file("s_labels.npy"));
  const LabelledScan pcd_scan = readScan(tmp.file("s.pcd"), "");
  EXPECT_EQ(npy_scan.points, bin.points);
  EXPECT_EQ(npy_scan.labels, bin.labels);
  EXPECT_EQ(pcd_scan.points, bin.points);
  EXPECT_EQ(pcd_scan.labels, bin.labels);
}

}  // namespace
}  // namespace sglc
