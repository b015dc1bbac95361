// KITTI / SemanticKITTI readers and writers.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <typeinfo>

#include "sglc/io.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::TempDir;

void writeBytes(const std::string& path, const std::vector<char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good());
}

void writeText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::trunc);
  out << text;
  ASSERT_TRUE(out.good());
}

// The message of the InputError thrown by f, or "" (and a test failure) when none is thrown.
template <typename F>
std::string inputErrorMessage(F&& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError, got another exception: " << e.what();
    return {};
  }
  ADD_FAILURE() << "expected InputError, nothing was thrown";
  return {};
}

Points samplePoints() {
  return {{1.5f, -2.25f, 0.125f}, {-40.0f, 12.5f, -1.75f}, {0.0f, 0.0f, 0.0f}, {79.9f, -0.001f, 3.0f}};
}

TEST(Io, KittiBinRoundTrip) {
  TempDir dir;
  const Points pts = samplePoints();
  const std::vector<float> refl{0.0f, 0.25f, 0.5f, 0.99f};
  writeKittiBin(dir.file("a.bin"), pts, refl);
  EXPECT_EQ(std::filesystem::file_size(dir.file("a.bin")), pts.size() * 16);
  std::vector<float> refl_back;
  const Points back = readKittiBin(dir.file("a.bin"), &refl_back);
  ASSERT_EQ(back.size(), pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    EXPECT_EQ(back[i], pts[i]) << "point " << i;  // float32 written and read back: bit-exact
    EXPECT_EQ(refl_back[i], refl[i]);
  }
  // Without reflectances the file still has 4 floats per point, the fourth 0.
  writeKittiBin(dir.file("b.bin"), pts, {});
  const Points back_b = readKittiBin(dir.file("b.bin"), &refl_back);
  EXPECT_EQ(back_b, pts);
  for (float r : refl_back) EXPECT_EQ(r, 0.0f);
}

TEST(Io, KittiBinLayoutIsFloat32XYZR) {
  // Independent of writeKittiBin: hand-made bytes in the documented layout.
  TempDir dir;
  const float raw[8] = {1.0f, 2.0f, 3.0f, 0.5f, -4.0f, -5.5f, 6.25f, 0.0f};
  std::vector<char> bytes(sizeof(raw));
  std::memcpy(bytes.data(), raw, sizeof(raw));
  writeBytes(dir.file("h.bin"), bytes);
  std::vector<float> refl;
  const Points pts = readKittiBin(dir.file("h.bin"), &refl);
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_EQ(pts[0], Vec3f(1.0f, 2.0f, 3.0f));
  EXPECT_EQ(pts[1], Vec3f(-4.0f, -5.5f, 6.25f));
  EXPECT_EQ(refl, (std::vector<float>{0.5f, 0.0f}));
}

TEST(Io, LabelsRoundTripAndScan) {
  TempDir dir;
  const Points pts = samplePoints();
  const std::vector<std::uint32_t> labels{10, 40 | (7u << 16), 0, 0xFFFFFFFFu};
  writeKittiBin(dir.file("s.bin"), pts, {});
  writeLabels(dir.file("s.label"), labels);
  EXPECT_EQ(readLabels(dir.file("s.label")), labels);
  const LabelledScan scan = readScan(dir.file("s.bin"), dir.file("s.label"));
  EXPECT_EQ(scan.points, pts);
  EXPECT_EQ(scan.labels, labels);
}

TEST(Io, EmptyFilesGiveEmptyScan) {
  TempDir dir;
  writeKittiBin(dir.file("e.bin"), {}, {});
  writeLabels(dir.file("e.label"), {});
  const LabelledScan scan = readScan(dir.file("e.bin"), dir.file("e.label"));
  EXPECT_TRUE(scan.points.empty());
  EXPECT_TRUE(scan.labels.empty());
}

TEST(Io, TruncatedBinNamesTheFile) {
  TempDir dir;
  writeBytes(dir.file("trunc.bin"), std::vector<char>(16 * 3 + 7, 0));
  const std::string msg = inputErrorMessage([&] { readKittiBin(dir.file("trunc.bin")); });
  EXPECT_NE(msg.find(dir.file("trunc.bin")), std::string::npos) << msg;
}

TEST(Io, TruncatedLabelsNamesTheFile) {
  TempDir dir;
  writeBytes(dir.file("trunc.label"), std::vector<char>(4 * 5 + 2, 0));
  const std::string msg = inputErrorMessage([&] { readLabels(dir.file("trunc.label")); });
  EXPECT_NE(msg.find(dir.file("trunc.label")), std::string::npos) << msg;
}

TEST(Io, LabelCountMismatch) {
  TempDir dir;
  writeKittiBin(dir.file("m.bin"), samplePoints(), {});
  writeLabels(dir.file("m.label"), {1, 2, 3});
  const std::string msg = inputErrorMessage([&] { readScan(dir.file("m.bin"), dir.file("m.label")); });
  EXPECT_NE(msg.find("m.label"), std::string::npos) << msg;
}

TEST(Io, NonFiniteCoordinateRejected) {
  TempDir dir;
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                    -std::numeric_limits<float>::infinity()}) {
    for (int axis = 0; axis < 3; ++axis) {
      Points pts = samplePoints();
      pts[2][axis] = bad;
      writeKittiBin(dir.file("nan.bin"), pts, {});
      const std::string msg = inputErrorMessage([&] { readKittiBin(dir.file("nan.bin")); });
      EXPECT_NE(msg.find("nan.bin"), std::string::npos) << msg;
      EXPECT_NE(msg.find("point 2"), std::string::npos) << msg;
    }
  }
  // A non-finite reflectance is not a coordinate: accepted.
  Points pts = samplePoints();
  writeKittiBin(dir.file("refl.bin"), pts, {0, std::numeric_limits<float>::quiet_NaN(), 0, 0});
  EXPECT_NO_THROW(readKittiBin(dir.file("refl.bin")));
}

TEST(Io, MissingFilesRejected) {
  TempDir dir;
  const std::string missing = dir.file("does_not_exist.bin");
  EXPECT_NE(inputErrorMessage([&] { readKittiBin(missing); }).find(missing), std::string::npos);
  EXPECT_NE(inputErrorMessage([&] { readLabels(missing); }).find(missing), std::string::npos);
  EXPECT_NE(inputErrorMessage([&] { readPoses(missing); }).find(missing), std::string::npos);
  EXPECT_NE(inputErrorMessage([&] { readCalibTr(missing); }).find(missing), std::string::npos);
  EXPECT_THROW(readScan(missing, dir.file("x.label")), InputError);
  // Writing into a directory that does not exist.
  EXPECT_THROW(writeKittiBin(dir.file("no/such/dir.bin"), samplePoints(), {}), InputError);
  EXPECT_THROW(writeLabels(dir.file("no/such/dir.label"), {1}), InputError);
  EXPECT_THROW(writePoses(dir.file("no/such/poses.txt"), {Mat4d::Identity()}), InputError);
}

// The documented contract: every failure is an InputError. A directory opens as a stream on Linux and its
// "size" (tellg at the end) is huge, so this is run in a child process: under AddressSanitizer the resulting
// giant allocation aborts instead of throwing std::bad_alloc.
TEST(IoDeathTest, DirectoryInsteadOfFileIsInputError) {
  TempDir dir;
  const std::string path = dir.path().string();
  for (int which = 0; which < 2; ++which) {
    EXPECT_EXIT(
        {
          try {
            if (which == 0)
              (void)readKittiBin(path);
            else
              (void)readLabels(path);
          } catch (const InputError&) {
            std::exit(0);
          } catch (const std::exception& e) {
            std::fprintf(stderr, "threw %s: %s\n", typeid(e).name(), e.what());
            std::exit(2);
          }
          std::exit(1);
        },
        ::testing::ExitedWithCode(0), "")
        << (which == 0 ? "readKittiBin" : "readLabels") << " on a directory must throw InputError";
  }
}

TEST(Io, WriteKittiBinIntensityCountMismatch) {
  TempDir dir;
  EXPECT_THROW(writeKittiBin(dir.file("x.bin"), samplePoints(), {0.1f}), InputError);
}

TEST(Io, PosesRoundTrip) {
  TempDir dir;
  std::vector<Mat4d> poses{Mat4d::Identity(), test::makeT(37.5, 12.25, -3.5, 0.75, 2.0, -1.0),
                           test::makeT(-179.0, -1234.5678, 0.001, 98.7)};
  writePoses(dir.file("poses.txt"), poses);
  const auto back = readPoses(dir.file("poses.txt"));
  ASSERT_EQ(back.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    // Written with 10 significant digits.
    EXPECT_TRUE(back[i].isApprox(poses[i], 1e-9)) << i << "\n" << back[i] << "\nvs\n" << poses[i];
    EXPECT_EQ(back[i].row(3), Eigen::RowVector4d(0, 0, 0, 1));
  }
}

TEST(Io, PosesHandWrittenFile) {
  TempDir dir;
  writeText(dir.file("p.txt"),
            "# comment line\n"
            "1 0 0 0 0 1 0 0 0 0 1 0\n"
            "\n"
            "0 -1 0 5.5 1 0 0 -2 0 0 1 0.25\n");
  const auto poses = readPoses(dir.file("p.txt"));
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_EQ(poses[0], Mat4d::Identity());
  Mat4d expected;
  expected << 0, -1, 0, 5.5, 1, 0, 0, -2, 0, 0, 1, 0.25, 0, 0, 0, 1;
  EXPECT_EQ(poses[1], expected);
}

TEST(Io, PosesMalformedLineNamesLineNumber) {
  TempDir dir;
  const std::string good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  // Line 3: only 11 numbers.
  writeText(dir.file("short.txt"), good + good + "1 0 0 0 0 1 0 0 0 0 1\n" + good);
  std::string msg = inputErrorMessage([&] { readPoses(dir.file("short.txt")); });
  EXPECT_NE(msg.find("short.txt:3"), std::string::npos) << msg;
  // Line 2: 13 numbers.
  writeText(dir.file("long.txt"), good + "1 0 0 0 0 1 0 0 0 0 1 0 7\n");
  msg = inputErrorMessage([&] { readPoses(dir.file("long.txt")); });
  EXPECT_NE(msg.find("long.txt:2"), std::string::npos) << msg;
  // Line 1: garbage.
  writeText(dir.file("text.txt"), "1 0 0 zero 0 1 0 0 0 0 1 0\n");
  msg = inputErrorMessage([&] { readPoses(dir.file("text.txt")); });
  EXPECT_NE(msg.find("text.txt:1"), std::string::npos) << msg;
}

TEST(Io, CalibTrFromFullCalibFile) {
  TempDir dir;
  // The layout of a KITTI odometry calib.txt: P0..P3, then Tr.
  writeText(dir.file("calib.txt"),
            "P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 0.000000000000e+00 "
            "7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 "
            "1.000000000000e+00 0.000000000000e+00\n"
            "P1: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.861448000000e+02 0.000000000000e+00 "
            "7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 "
            "1.000000000000e+00 0.000000000000e+00\n"
            "P2: 1 2 3 4 5 6 7 8 9 10 11 12\n"
            "P3: 1 2 3 4 5 6 7 8 9 10 11 12\n"
            "Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 "
            "-7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 "
            "9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01\n");
  const Mat4d Tr = readCalibTr(dir.file("calib.txt"));
  EXPECT_DOUBLE_EQ(Tr(0, 0), 4.276802385584e-04);
  EXPECT_DOUBLE_EQ(Tr(0, 1), -9.999672484946e-01);
  EXPECT_DOUBLE_EQ(Tr(0, 3), -1.198459927713e-02);
  EXPECT_DOUBLE_EQ(Tr(1, 2), -9.999413164504e-01);
  EXPECT_DOUBLE_EQ(Tr(2, 0), 9.999738645903e-01);
  EXPECT_DOUBLE_EQ(Tr(2, 3), -2.921968648686e-01);
  EXPECT_EQ(Tr.row(3), Eigen::RowVector4d(0, 0, 0, 1));
  // It is (numerically) a rotation.
  const Mat3d R = Tr.topLeftCorner<3, 3>();
  EXPECT_NEAR((R * R.transpose() - Mat3d::Identity()).norm(), 0.0, 1e-6);
}

TEST(Io, CalibWithoutTrRejected) {
  TempDir dir;
  writeText(dir.file("calib.txt"), "P0: 1 2 3 4 5 6 7 8 9 10 11 12\nTr_imu_velo 1 2 3\n");
  const std::string msg = inputErrorMessage([&] { readCalibTr(dir.file("calib.txt")); });
  EXPECT_NE(msg.find("calib.txt"), std::string::npos) << msg;
  EXPECT_NE(msg.find("Tr"), std::string::npos) << msg;
  writeText(dir.file("bad_tr.txt"), "Tr: 1 2 3\n");
  EXPECT_THROW(readCalibTr(dir.file("bad_tr.txt")), InputError);
}

TEST(Io, RealCalibFile) {
  SGLC_REQUIRE_REAL_DATA();
  const Mat4d Tr = readCalibTr(test::scansDir() + "/sequences/00/calib.txt");
  // KITTI 00 Tr (velodyne -> cam0), published values.
  EXPECT_DOUBLE_EQ(Tr(0, 1), -9.999672484946e-01);
  EXPECT_DOUBLE_EQ(Tr(2, 3), -2.921968648686e-01);
}

TEST(Io, RealScanReads) {
  SGLC_REQUIRE_REAL_DATA();
  const std::string dir = test::scansDir() + "/sequences/00";
  const LabelledScan scan = readScan(dir + "/velodyne/000052.bin", dir + "/labels/000052.label");
  EXPECT_EQ(scan.points.size() * 16, std::filesystem::file_size(dir + "/velodyne/000052.bin"));
  EXPECT_EQ(scan.labels.size(), scan.points.size());
  EXPECT_GT(scan.points.size(), 100000u);  // an HDL-64 scan (SOURCE.md: 120-127 k points)
}

}  // namespace
}  // namespace sglc
