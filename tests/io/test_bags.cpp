// Bags in: MCAP (zstd, lz4, uncompressed) and rosbag2 .db3 written by @mcap/core, Foxglove's CDR serialiser and
// Python's sqlite3, read by the project's readers (sglc/bag.hpp, sglc/ros_messages.hpp, sglc/bag_drive.hpp).
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <cmath>
#include <fstream>

#include "bag_writer.hpp"
#include "sglc/bag.hpp"
#include "sglc/bag_drive.hpp"
#include "sglc/ros_messages.hpp"
#include "test_util.hpp"

using namespace sglc;
using namespace sglc::test;

namespace {

constexpr std::int64_t kT0 = 1700000000LL * 1000000000LL;  // a stamp in 2023, in ns

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

// The five time conventions, each a cloud of three points at 0, 25 and 50 ms after the stamp; one NaN point.
json conventions() {
  const double t0 = static_cast<double>(kT0);
  json xyz = {field("x", 0, 7), field("y", 4, 7), field("z", 8, 7)};
  auto with = [&](json fields, const json& f) {
    fields.push_back(f);
    return fields;
  };
  json messages = json::array();
  // Ouster: t uint32 ns
  messages.push_back(cloud("/ouster", kT0, with(xyz, field("t", 12, 6)), 16,
                           {{1, 2, 3, 0}, {nullptr, 0, 0, 1}, {4, 5, 6, 25000000}, {7, 8, 9, 50000000}}));
  // Velodyne: time float32 s (here before the stamp too)
  messages.push_back(cloud("/velodyne", kT0, with(xyz, field("time", 16, 7)), 20,
                           {{1, 2, 3, -0.05}, {4, 5, 6, 0.025}, {7, 8, 9, 0.05}}));
  // Livox: offset_time uint32 ns
  messages.push_back(cloud("/livox", kT0, with(xyz, field("offset_time", 12, 6)), 16,
                           {{1, 2, 3, 0}, {4, 5, 6, 25000000}, {7, 8, 9, 50000000}}));
  // Hesai: timestamp float64 absolute s
  messages.push_back(cloud("/hesai", kT0, with(xyz, field("timestamp", 16, 8)), 24,
                           {{1, 2, 3, t0 * 1e-9}, {4, 5, 6, t0 * 1e-9 + 0.025}, {7, 8, 9, t0 * 1e-9 + 0.05}}));
  // Livox (driver 2): timestamp float64 absolute ns
  messages.push_back(cloud("/livox2", kT0, with(xyz, field("timestamp", 16, 8)), 24,
                           {{1, 2, 3, t0}, {4, 5, 6, t0 + 25e6}, {7, 8, 9, t0 + 50e6}}));
  return messages;
}

void expectConventions(Bag& bag) {
  const struct {
    const char* topic;
    double first;
  } expected[] = {{"/ouster", 0.0}, {"/velodyne", -0.05}, {"/livox", 0.0}, {"/hesai", 0.0}, {"/livox2", 0.0}};
  for (const auto& e : expected) {
    SCOPED_TRACE(e.topic);
    const std::size_t topic = bag.topic(e.topic);
    EXPECT_EQ(bag.topics()[topic].type, "sensor_msgs/msg/PointCloud2");
    const auto messages = bag.messages({topic});
    ASSERT_EQ(messages.size(), 1u);
    EXPECT_EQ(headerStampOf(messages[0], bag.topics()[topic].encoding, "x"), kT0);
    const RosCloud c =
        decodePointCloud2(bag.read(messages[0]), bag.topics()[topic].encoding, 1000, bag.where(messages[0]));
    EXPECT_EQ(c.stamp_ns, kT0);
    EXPECT_EQ(c.frame_id, "lidar");
    ASSERT_EQ(c.points.size(), 3u);
    EXPECT_EQ(c.dropped, std::string(e.topic) == "/ouster" ? 1u : 0u);
    EXPECT_EQ(c.points[2], Vec3f(7, 8, 9));
    ASSERT_EQ(c.times.size(), 3u);
    EXPECT_NEAR(c.times[0], e.first, 1e-6);
    EXPECT_NEAR(c.times[1], 0.025, 2e-6);  // absolute float64 seconds keep about a microsecond
    EXPECT_NEAR(c.times[2], 0.05, 2e-6);
  }
}

}  // namespace

TEST(Bags, McapInEveryCompressionAndDb3GiveEveryTimeConvention) {
  TempDir tmp;
  for (const std::string storage : {"zstd", "lz4", "", "db3", "ros1-none", "ros1-bz2", "ros1-lz4"}) {
    SCOPED_TRACE("storage " + storage);
    const bool ros1 = storage.rfind("ros1", 0) == 0;
    json spec = {{"storage", storage == "db3" ? "db3"
                             : ros1           ? "ros1"
                                              : "mcap"},
                 {"compression", ros1 ? storage.substr(5) : storage},
                 {"messages", conventions()}};
    const std::string out = tmp.file(storage == "db3" ? "db3bag"
                                     : ros1           ? storage + ".bag"
                                                      : "bag-" + storage + ".mcap");
    writeBag(spec, out);
    ASSERT_TRUE(isBag(out));
    auto bag = openBag(out);
    EXPECT_EQ(bag->topics().size(), 5u);
    for (const auto& t : bag->topics())
      EXPECT_EQ(t.encoding, ros1 ? MessageEncoding::kRos1 : MessageEncoding::kCdr) << t.name;
    expectConventions(*bag);
  }
}

TEST(Bags, OrganisedBigEndianFloat64CloudsDropTheirNaNs) {
  TempDir tmp;
  // 2 rows x 3 columns, float64 x y z and float32 intensity, big-endian; three points NaN (an organised
  // cloud's missing returns).
  json fields = {field("x", 0, 8), field("y", 8, 8), field("z", 16, 8), field("intensity", 24, 7)};
  json points = {{1.5, 2, 3, 10},   {nullptr, nullptr, nullptr, 0}, {4, 5, 6.25, 20}, {nullptr, 1, 1, 0}, {7, 8, 9, 30},
                 {1, nullptr, 1, 0}};
  json spec = {
      {"storage", "mcap"}, {"compression", "zstd"}, {"messages", {cloud("/os", kT0, fields, 28, points, 2, true)}}};
  writeBag(spec, tmp.file("b.mcap"));
  auto bag = openBag(tmp.file("b.mcap"));
  const auto m = bag->messages({bag->topic("/os")});
  const RosCloud c = decodePointCloud2(bag->read(m.at(0)), MessageEncoding::kCdr, 100, "x");
  EXPECT_EQ(c.width, 3u);
  EXPECT_EQ(c.height, 2u);
  EXPECT_EQ(c.dropped, 3u);
  ASSERT_EQ(c.points.size(), 3u);
  EXPECT_EQ(c.points[0], Vec3f(1.5f, 2, 3));
  EXPECT_EQ(c.points[1], Vec3f(4, 5, 6.25f));
  EXPECT_EQ(c.intensities, (std::vector<float>{10, 20, 30}));
  EXPECT_TRUE(c.times.empty());
}

TEST(Bags, DriveFromOdometryWithTheSensorExtrinsicAndKeyframes) {
  TempDir tmp;
  json xyz = {field("x", 0, 7), field("y", 4, 7), field("z", 8, 7)};
  json messages = json::array();
  // The base drives along x at 5 m/s, odometry at 20 Hz; clouds at 10 Hz, 20 ms after odometry ticks; the
  // LiDAR sits 1 m ahead of the base and 1.8 m up, turned 90 deg (from /tf_static).
  for (int i = 0; i <= 40; ++i) messages.push_back(odometry("/odom", kT0 + i * 50000000LL, 0.25 * i, 0, 0));
  for (int k = 0; k < 20; ++k)
    messages.push_back(cloud("/points", kT0 + k * 100000000LL + 20000000LL, xyz, 12, {{1, 0, 0}, {0, 1, 0}}));
  messages.push_back(tf("/tf_static", kT0, {transform(kT0, "base_link", "lidar", 1.0, 0, 1.8, M_PI / 2)}));
  writeBag({{"storage", "mcap"}, {"compression", "lz4"}, {"messages", messages}}, tmp.file("drive.mcap"));

  BagDriveOptions o;
  o.points_topic = "/points";
  o.odom_topic = "/odom";
  o.keyframe_m = 0.9;
  BagDrive drive(tmp.file("drive.mcap"), o);
  EXPECT_EQ(drive.clouds(), 20u);
  EXPECT_TRUE(drive.warnings().empty()) << drive.warnings().front();
  // 0.5 m per cloud: every 2nd cloud is a keyframe (1 m from the last).
  ASSERT_EQ(drive.frames().size(), 10u);
  for (std::size_t i = 0; i < drive.frames().size(); ++i) {
    const auto& f = drive.frames()[i];
    EXPECT_EQ(f.number, static_cast<std::int64_t>(2 * i));
    ASSERT_TRUE(f.pose);
    // Interpolated between odometry ticks: base at 5 m/s * t, plus the extrinsic.
    const double base_x = 5.0 * (static_cast<double>(f.stamp_ns - kT0) * 1e-9);
    EXPECT_NEAR((*f.pose)(0, 3), base_x + 1.0, 1e-9);
    EXPECT_NEAR((*f.pose)(2, 3), 1.8, 1e-9);
    EXPECT_NEAR((*f.pose)(1, 0), 1.0, 1e-9);  // the LiDAR's x points along the base's y
  }
  EXPECT_EQ(drive.cloud(3).points.size(), 2u);
  EXPECT_FALSE(drive.cloud(3).deskewed);  // no per-point times
  EXPECT_TRUE(drive.frames()[3].twist);
  EXPECT_NEAR(drive.frames()[3].twist->linear.norm(), 5.0, 1e-6);  // the base's 5 m/s, in the sensor's axes

  // The same drive in a ROS 1 bag (Debian's python3-rosbag, bz2 chunks): the same keyframes and poses.
  writeBag({{"storage", "ros1"}, {"compression", "bz2"}, {"messages", messages}}, tmp.file("drive.bag"));
  BagDrive ros1(tmp.file("drive.bag"), o);
  ASSERT_EQ(ros1.frames().size(), drive.frames().size());
  for (std::size_t i = 0; i < drive.frames().size(); ++i) {
    EXPECT_EQ(ros1.frames()[i].stamp_ns, drive.frames()[i].stamp_ns);
    EXPECT_TRUE(ros1.frames()[i].pose->isApprox(*drive.frames()[i].pose, 1e-9)) << i;
  }
  EXPECT_EQ(ros1.cloud(3).points, drive.cloud(3).points);

  // Every cloud when both thresholds are 0.
  o.keyframe_m = o.keyframe_deg = 0;
  EXPECT_EQ(BagDrive(tmp.file("drive.mcap"), o).frames().size(), 20u);

  // The same drive from /tf: odom -> base_link dynamic, base_link -> lidar static.
  json tf_messages = json::array();
  for (int i = 0; i <= 40; ++i)
    tf_messages.push_back(
        tf("/tf", kT0 + i * 50000000LL, {transform(kT0 + i * 50000000LL, "odom", "base_link", 0.25 * i, 0, 0, 0)}));
  for (int k = 0; k < 20; ++k)
    tf_messages.push_back(cloud("/points", kT0 + k * 100000000LL + 20000000LL, xyz, 12, {{1, 0, 0}}));
  tf_messages.push_back(tf("/tf_static", kT0, {transform(kT0, "base_link", "lidar", 1.0, 0, 1.8, M_PI / 2)}));
  writeBag({{"storage", "db3"}, {"compression", ""}, {"messages", tf_messages}}, tmp.file("tfbag"));
  BagDriveOptions t;
  t.points_topic = "/points";
  t.tf_frame = "odom";
  t.keyframe_m = 0.9;
  BagDrive by_tf(tmp.file("tfbag"), t);
  ASSERT_EQ(by_tf.frames().size(), 10u);
  for (std::size_t i = 0; i < 10; ++i)
    EXPECT_TRUE(by_tf.frames()[i].pose->isApprox(*drive.frames()[i].pose, 1e-9)) << i;
  t.tf_frame = "map";
  EXPECT_NE(errorOf([&] { BagDrive(tmp.file("tfbag"), t); }).find("frame map"), std::string::npos);
}

TEST(Bags, BadInputNamesFileTopicAndMessage) {
  TempDir tmp;
  json xyz = {field("x", 0, 7), field("y", 4, 7), field("z", 8, 7)};
  json messages = {cloud("/points", kT0, xyz, 12, {{1, 2, 3}}), odometry("/odom", kT0, 0, 0, 0)};
  writeBag({{"storage", "mcap"}, {"compression", "zstd"}, {"messages", messages}}, tmp.file("ok.mcap"));
  std::ifstream in(tmp.file("ok.mcap"), std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  auto write = [&](const std::string& name, const std::string& b) {
    std::ofstream(tmp.file(name), std::ios::binary) << b;
    return tmp.file(name);
  };
  BagDriveOptions o;
  o.points_topic = "/points";

  // A FIFO or a directory without metadata.yaml is refused at once, never waited on.
  ASSERT_EQ(::mkfifo(tmp.file("fifo.mcap").c_str(), 0600), 0);
  EXPECT_NE(errorOf([&] { openBag(tmp.file("fifo.mcap")); }).find("not a regular file"), std::string::npos);
  EXPECT_NE(errorOf([&] { openBag(tmp.path().string()); }).find("without metadata.yaml"), std::string::npos);
  EXPECT_NE(errorOf([&] { openBag(tmp.file("none.mcap")); }).find("no such file"), std::string::npos);

  // A topic that is not there: the ones that are, with their types.
  o.points_topic = "/velodyne_points";
  std::string msg = errorOf([&] { BagDrive(tmp.file("ok.mcap"), o); });
  EXPECT_NE(msg.find("no topic /velodyne_points"), std::string::npos) << msg;
  EXPECT_NE(msg.find("/points (sensor_msgs/msg/PointCloud2, 1 messages)"), std::string::npos) << msg;
  // A topic of another type.
  o.points_topic = "/odom";
  msg = errorOf([&] { BagDrive(tmp.file("ok.mcap"), o); });
  EXPECT_NE(msg.find("carries nav_msgs/msg/Odometry, not sensor_msgs/PointCloud2"), std::string::npos) << msg;
  o.points_topic = "/points";

  // Truncated anywhere before the end of its data section: an error, never a crash or a hang. (Cut after the
  // DataEnd record, every message is still there and is read.)
  const auto data_end = bytes.find(std::string("\x0f\x04\0\0\0\0\0\0\0", 9));
  ASSERT_NE(data_end, std::string::npos);
  for (std::size_t cut = 0; cut < data_end; cut += 5) {
    const std::string path = write("cut.mcap", bytes.substr(0, cut));
    msg = errorOf([&] { BagDrive(path, o).cloud(0); });
    EXPECT_NE(msg, "(no error)") << "cut at " << cut;
  }
  // A flipped byte inside the chunk's compressed records: zstd or the CRC says so.
  const auto chunk = bytes.find("zstd");
  ASSERT_NE(chunk, std::string::npos);
  std::string flipped = bytes;
  flipped[chunk + 30] = static_cast<char>(flipped[chunk + 30] ^ 0x5a);
  msg = errorOf([&] { BagDrive(write("flip.mcap", flipped), o).cloud(0); });
  EXPECT_TRUE(msg.find("CRC mismatch") != std::string::npos || msg.find("zstd data") != std::string::npos) << msg;
  EXPECT_NE(msg.find("flip.mcap"), std::string::npos) << msg;
  // A chunk claiming 1 GiB from a few hundred bytes: refused before any memory is taken.
  std::string bomb = bytes;
  const std::uint64_t gib = 1ull << 30;
  bomb.replace(chunk - 16, 8, std::string(reinterpret_cast<const char*>(&gib), 8));
  msg = errorOf([&] { openBag(write("bomb.mcap", bomb)); });
  EXPECT_NE(msg.find("decompression bomb"), std::string::npos) << msg;
  // An unknown compression.
  std::string brotli = bytes;
  brotli.replace(chunk, 4, "brot");
  msg = errorOf([&] { openBag(write("brot.mcap", brotli)); });
  EXPECT_NE(msg.find("compression 'brot'"), std::string::npos) << msg;

  // Layouts that lie, patched into an unchunked MCAP (no CRC over them) of one cloud of 3 points: 10^8 points
  // claimed with no data behind them; a field outside the point; a row_step too short for the width.
  writeBag({{"storage", "mcap"},
            {"compression", "nochunks"},
            {"messages", {cloud("/points", kT0, xyz, 12, {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}})}}},
           tmp.file("plain.mcap"));
  std::ifstream pin(tmp.file("plain.mcap"), std::ios::binary);
  const std::string plain((std::istreambuf_iterator<char>(pin)), {});
  auto patched = [&](const std::string& from, const std::string& to) {
    const auto at = plain.find(from);
    EXPECT_NE(at, std::string::npos);
    std::string b = plain;
    if (at != std::string::npos) b.replace(at, from.size(), to);
    return b;
  };
  const std::string dims("\x01\0\0\0\x03\0\0\0", 8);   // height 1, width 3
  const std::string z_field("z\0\0\0\x08\0\0\0", 8);   // "z" NUL, padding, offset 8
  const std::string steps("\x0c\0\0\0\x24\0\0\0", 8);  // point_step 12, row_step 36
  for (const auto& [name, from, to, expected] :
       {std::tuple{"huge", dims, std::string("\x01\0\0\0\x00\xe1\xf5\x05", 8), "more than the limit"},
        std::tuple{"outside", z_field, std::string("z\0\0\0\x0a\0\0\0", 8), "lies outside the point_step"},
        std::tuple{"rows", steps, std::string("\x0c\0\0\0\x10\0\0\0", 8), "lies about its sizes"}}) {
    SCOPED_TRACE(name);
    const std::string path = write(std::string(name) + ".mcap", patched(from, to));
    msg = errorOf([&] { BagDrive(path, o).cloud(0); });
    EXPECT_NE(msg.find(expected), std::string::npos) << msg;
    EXPECT_NE(msg.find("topic /points, message 0"), std::string::npos) << msg;
    EXPECT_NE(msg.find(name), std::string::npos) << msg;
  }
}

TEST(Bags, CloudsWithPointTimesAreDeskewedWithTheOdometry) {
  TempDir tmp;
  // The sensor drives along its x at 10 m/s; a wall point 20 m ahead is measured at 0, 50 and 99 ms after
  // the stamp: the sensor is then 0, 0.5 and 0.99 m further on, so the raw x is 20, 19.5 and 19.01 m.
  json fields = {field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("t", 12, 6)};
  json messages = json::array();
  for (int i = 0; i <= 20; ++i) messages.push_back(odometry("/odom", kT0 + i * 50000000LL, 0.5 * i, 0, 0, "lidar"));
  messages.push_back(cloud("/points", kT0 + 300000000LL, fields, 16,
                           {{20, 0, 0, 0}, {19.5, 1, 0, 50000000}, {19.01, 2, 0, 99000000}}));
  writeBag({{"storage", "mcap"}, {"compression", "zstd"}, {"messages", messages}}, tmp.file("d.mcap"));
  BagDriveOptions o;
  o.points_topic = "/points";
  o.odom_topic = "/odom";
  BagDrive drive(tmp.file("d.mcap"), o);
  ASSERT_EQ(drive.frames().size(), 1u);
  const RosCloud c = drive.cloud(0);
  EXPECT_TRUE(c.deskewed);
  ASSERT_EQ(c.points.size(), 3u);
  for (const auto& p : c.points) EXPECT_NEAR(p.x(), 20.0, 1e-4) << p.transpose();
  o.deskew = false;
  const RosCloud raw = BagDrive(tmp.file("d.mcap"), o).cloud(0);
  EXPECT_FALSE(raw.deskewed);
  EXPECT_NEAR(raw.points[2].x(), 19.01, 1e-5);
}
