// The scan file limits of sglc/scan_file.hpp: regular files only (a FIFO is refused, never waited on), the point
// cap and the size limit judged from the file size or header before the data is read, and ASCII PCD/PLY values
// read as their declared types.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>

#include "io_files.hpp"
#include "sglc/io.hpp"
#include "sglc/npy.hpp"
#include "sglc/scan_file.hpp"
#include "sglc/sequence.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::errorOf;
using test::TempDir;
using test::writeBytes;

// A file of `size` bytes that starts with `head`; the rest is a hole (no disk space, reads as zeros).
std::string sparseFile(const std::string& path, const std::string& head, std::uint64_t size) {
  writeBytes(path, head);
  std::filesystem::resize_file(path, size);
  return path;
}

// f's InputError, or a failure (not a hang) when f is still blocked on the FIFO at `fifo` after 30 s: a writer
// then opens and closes the FIFO, which ends the blocked read.
std::string errorWithin30s(const std::string& fifo, const std::function<void()>& f) {
  auto result = std::async(std::launch::async, [&] { return errorOf(f); });
  if (result.wait_for(std::chrono::seconds(30)) == std::future_status::ready) return result.get();
  const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
  if (fd >= 0) ::close(fd);
  result.wait();
  return "(blocked on the FIFO for 30 s)";
}

std::string npyHeader(const std::string& shape, const std::string& descr = "<f4") {
  return test::npy("{'descr': '" + descr + "', 'fortran_order': False, 'shape': " + shape + ", }", "");
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(ScanLimits, AFifoIsRefusedNotWaitedOn) {
  TempDir dir;
  for (const char* name : {"f.bin", "f.npy", "f.pcd", "f.ply"}) {
    const std::string fifo = dir.file(name);
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    const std::string msg = errorWithin30s(fifo, [&] { readScan(fifo, ""); });
    EXPECT_TRUE(has(msg, fifo + ": is a FIFO")) << msg;
  }
  // Label, poses and stamps files too.
  writeKittiBin(dir.file("ok.bin"), {{1, 2, 3}}, {0});
  const std::string labels = dir.file("l.label");
  ASSERT_EQ(::mkfifo(labels.c_str(), 0600), 0);
  EXPECT_TRUE(has(errorWithin30s(labels, [&] { readScan(dir.file("ok.bin"), labels); }), "is a FIFO"));
  const std::string poses = dir.file("poses.txt");
  ASSERT_EQ(::mkfifo(poses.c_str(), 0600), 0);
  EXPECT_TRUE(has(errorWithin30s(poses, [&] { readPoses(poses); }), "is a FIFO"));
}

TEST(ScanLimits, AFifoInASequenceIsRefusedWhenItsScanIsRead) {
  TempDir dir;
  std::filesystem::create_directories(dir.path() / "velodyne");
  writeKittiBin((dir.path() / "velodyne/000000.bin").string(), {{1, 2, 3}}, {0});
  const std::string fifo = (dir.path() / "velodyne/000001.bin").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const Sequence seq = openSequence(dir.path().string());
  ASSERT_EQ(seq.frames.size(), 2u);
  EXPECT_EQ(readScan(seq.frames[0].scan_path, "").points.size(), 1u);
  EXPECT_TRUE(has(errorWithin30s(fifo, [&] { readScan(seq.frames[1].scan_path, ""); }), "is a FIFO"));
}

TEST(ScanLimits, SparseGiantsAreRefusedFromTheirSizeOrHeader) {
  TempDir dir;
  const std::uint64_t giant = std::uint64_t{2} << 30;
  const std::uint64_t n = giant / 16;
  const std::string pcd = "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " + std::to_string(n) +
                          "\nHEIGHT 1\nPOINTS " + std::to_string(n) + "\nDATA binary\n";
  const std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) +
                          "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  const std::pair<std::string, std::string> giants[] = {
      {sparseFile(dir.file("g.bin"), "", giant), std::to_string(n) + " points (16 bytes each in the file)"},
      {sparseFile(dir.file("g.npy"), npyHeader("(" + std::to_string(n) + ", 4)"), giant), "bytes, larger than"},
      {sparseFile(dir.file("g.pcd"), pcd, giant), "bytes, larger than"},
      {sparseFile(dir.file("g.ply"), ply, giant), "bytes, larger than"},
  };
  for (const auto& giant_file : giants) {
    const auto& [path, reason] = giant_file;
    const std::string msg = errorOf([&giant_file] { readScan(giant_file.first, ""); });
    EXPECT_TRUE(has(msg, path + ": ") && has(msg, reason)) << msg;
  }
}

TEST(ScanLimits, MoreThanTheCapIsRefusedFromTheHeaderBeforeTheData) {
  TempDir dir;
  const std::uint64_t n = kMaxScanPoints + 1;
  const std::string count = std::to_string(n);
  const std::string pcd = "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " + count +
                          "\nHEIGHT 1\nPOINTS " + count + "\nDATA binary\n";
  const std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex " + count +
                          "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  const std::string npy = npyHeader("(" + count + ", 3)");
  const std::string files[] = {
      sparseFile(dir.file("m.bin"), "", n * 16),
      sparseFile(dir.file("m.npy"), npy, npy.size() + n * 12),
      sparseFile(dir.file("m.pcd"), pcd, pcd.size() + n * 12),
      sparseFile(dir.file("m.ply"), ply, ply.size() + n * 12),
  };
  for (const auto& path : files) {
    const std::string msg = errorOf([&] { readScan(path, ""); });
    EXPECT_TRUE(has(msg, path + ": " + count + " points") && has(msg, "more than the 2000000")) << msg;
  }
  // npy labels are held to the cap as well; a scan of exactly the cap is not refused for its size.
  const std::string labels = npyHeader("(" + count + ",)", "<u4");
  EXPECT_TRUE(has(errorOf([&] { readNpyLabels(sparseFile(dir.file("l.npy"), labels, labels.size() + n * 4)); }),
                  "more than the 2000000"));
  EXPECT_EQ(readKittiBin(sparseFile(dir.file("cap.bin"), "", kMaxScanPoints * 16)).size(), kMaxScanPoints);
}

const std::string kPcdHead =
    "VERSION .7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\n"
    "POINTS 2\nDATA ascii\n1 2 3 40\n";

TEST(ScanLimits, AsciiPcdValuesMustFitTheirDeclaredType) {
  TempDir dir;
  const std::pair<std::string, std::string> bad[] = {
      {"4 5 6 -10", "line 11 of the file), field 'label' (U4): value '-10' is out of range for U4 (0..4294967295)"},
      {"4 5 6 10.5", "field 'label' (U4): value '10.5' is not an integer"},
      {"4 5 6 99999999999", "value '99999999999' is out of range for U4"},
      {"4 5 1e39 1", "field 'z' (F4): value '1e39' is not a finite F4 value"},
      {"4 5 inf 1", "value 'inf' is not a finite F4 value"},
  };
  for (const auto& [line, reason] : bad) {
    writeBytes(dir.file("bad.pcd"), kPcdHead + line + "\n");
    const std::string msg = errorOf([&] { readScan(dir.file("bad.pcd"), ""); });
    EXPECT_TRUE(has(msg, dir.file("bad.pcd") + ": PCD ascii line 2") && has(msg, reason)) << line << ": " << msg;
  }
  // Signed and narrow types: the limits themselves fit, one beyond does not.
  const std::string narrow =
      "VERSION .7\nFIELDS x y z a b\nSIZE 4 4 8 1 2\nTYPE F F F I U\nCOUNT 1 1 1 1 1\nWIDTH 1\nHEIGHT 1\n"
      "POINTS 1\nDATA ascii\n";
  writeBytes(dir.file("ok.pcd"), narrow + "+1.5 3.4028235e38 -2.5 -128 65535\n");
  EXPECT_EQ(readScan(dir.file("ok.pcd"), "").points.size(), 1u);
  writeBytes(dir.file("i1.pcd"), narrow + "1 2 3 -129 0\n");
  EXPECT_TRUE(has(errorOf([&] { readScan(dir.file("i1.pcd"), ""); }), "'-129' is out of range for I1 (-128..127)"));
  writeBytes(dir.file("u2.pcd"), narrow + "1 2 3 0 65536\n");
  EXPECT_TRUE(has(errorOf([&] { readScan(dir.file("u2.pcd"), ""); }), "'65536' is out of range for U2 (0..65535)"));
  // The largest U4 label is read as itself (a float field would have lost it).
  writeBytes(dir.file("max.pcd"), kPcdHead + "4 5 6 4294967295\n");
  EXPECT_EQ(readScan(dir.file("max.pcd"), "").labels, (std::vector<std::uint32_t>{40, 4294967295u}));
}

TEST(ScanLimits, AsciiPlyValuesMustFitTheirDeclaredType) {
  TempDir dir;
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty int ring\nend_header\n"
      "1 2 3 10 20 30 7\n";
  const std::pair<std::string, std::string> bad[] = {
      {"4 5 6 300 0 0 1", "PLY vertex 1 (line 13), property 'red' (U1): value '300' is out of range for U1 (0..255)"},
      {"4 5 6 0 -1 0 1", "property 'green' (U1): value '-1' is out of range"},
      {"4 5 6 0 0 0 2.5", "property 'ring' (I4): value '2.5' is not an integer"},
      {"4 5 6 0 0 0 2147483648", "value '2147483648' is out of range for I4"},
      {"4 5 six 0 0 0 1", "property 'z' (F4): value 'six' is not a number"},
      {"4 5 6 0 0 0", "PLY ascii data ends in vertex 1 of 2"},
  };
  for (const auto& [line, reason] : bad) {
    writeBytes(dir.file("bad.ply"), head + line + "\n");
    const std::string msg = errorOf([&] { readScan(dir.file("bad.ply"), ""); });
    EXPECT_TRUE(has(msg, dir.file("bad.ply") + ": ") && has(msg, reason)) << line << ": " << msg;
  }
  writeBytes(dir.file("ok.ply"), head + "4 5 6 255 0 0 -2147483648\n");
  EXPECT_EQ(readScan(dir.file("ok.ply"), "").points.size(), 2u);
}

}  // namespace
}  // namespace sglc
