// Test bags written by implementations nobody here wrote (tests/interop/write_bag.mjs: @mcap/core, Foxglove's
// ROS 2 CDR serialiser, Python's sqlite3), from a description built in the test.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace sglc::test {

using json = nlohmann::json;

inline std::string interopDir() { return std::string(SGLC_SOURCE_DIR) + "/tests/interop"; }

// Writes `spec` (see write_bag.mjs) to `out`; fails the test with the reason when node or the npm packages are
// missing (scripts/install-deps.sh installs them).
inline void writeBag(const json& spec, const std::string& out) {
  if (spec.value("storage", "") == "ros1") {
    // Debian's python3-rosbag writes ROS 1 bags.
    const std::string spec_path = out + ".spec.json";
    std::ofstream(spec_path) << spec.dump();
    const std::string cmd =
        "/usr/bin/python3 '" + interopDir() + "/write_ros1_bag.py' '" + spec_path + "' '" + out + "' 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd << " (python3-rosbag missing? run scripts/install-deps.sh)";
    return;
  }
  ASSERT_TRUE(std::filesystem::exists(interopDir() + "/node_modules/@mcap/core"))
      << "npm packages missing in tests/interop: run scripts/install-deps.sh";
  const std::string spec_path = out + ".spec.json";
  std::ofstream(spec_path) << spec.dump();
  const std::string cmd = "node '" + interopDir() + "/write_bag.mjs' '" + spec_path + "' '" + out + "' 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
}

inline json field(const std::string& name, int offset, int datatype) {
  return {{"name", name}, {"offset", offset}, {"datatype", datatype}, {"count", 1}};
}

// A PointCloud2 message of `points` (rows of values in field order; null for NaN).
inline json cloud(const std::string& topic, std::int64_t stamp_ns, const json& fields, int point_step,
                  const json& points, int height = 1, bool big_endian = false, const std::string& frame = "lidar") {
  return {{"topic", topic},
          {"type", "pointcloud2"},
          {"log_time_ns", std::to_string(stamp_ns + 5000000)},
          {"stamp_ns", std::to_string(stamp_ns)},
          {"frame_id", frame},
          {"height", height},
          {"width", points.size() / height},
          {"is_bigendian", big_endian},
          {"point_step", point_step},
          {"fields", fields},
          {"points", points}};
}

inline json odometry(const std::string& topic, std::int64_t stamp_ns, double x, double y, double yaw_rad,
                     const std::string& child = "base_link") {
  return {{"topic", topic},
          {"type", "odometry"},
          {"log_time_ns", std::to_string(stamp_ns)},
          {"stamp_ns", std::to_string(stamp_ns)},
          {"frame_id", "odom"},
          {"child_frame_id", child},
          {"position", {x, y, 0.0}},
          {"orientation", {0.0, 0.0, std::sin(yaw_rad / 2), std::cos(yaw_rad / 2)}}};
}

inline json transform(std::int64_t stamp_ns, const std::string& parent, const std::string& child, double x, double y,
                      double z, double yaw_rad) {
  return {{"stamp_ns", std::to_string(stamp_ns)},
          {"frame_id", parent},
          {"child_frame_id", child},
          {"position", {x, y, z}},
          {"orientation", {0.0, 0.0, std::sin(yaw_rad / 2), std::cos(yaw_rad / 2)}}};
}

inline json tf(const std::string& topic, std::int64_t log_time_ns, const json& transforms) {
  // A single transform given in braces arrives as the object itself: always send a list.
  const json list = transforms.is_array() ? transforms : json::array({transforms});
  return {{"topic", topic}, {"type", "tf"}, {"log_time_ns", std::to_string(log_time_ns)}, {"transforms", list}};
}

}  // namespace sglc::test
