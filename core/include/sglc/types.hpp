// Plain data types shared by every stage of the engine.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace sglc {

using Vec2d = Eigen::Vector2d;
using Vec3f = Eigen::Vector3f;
using Vec3d = Eigen::Vector3d;
using Mat3d = Eigen::Matrix3d;
using Mat4d = Eigen::Matrix4d;
using Mat6d = Eigen::Matrix<double, 6, 6>;
using Points = std::vector<Vec3f>;

// One LiDAR scan in its sensor frame: N points and one semantic label per point.
// Labels follow the SemanticKITTI convention: the low 16 bits are the class id, the high 16 bits an
// instance id that the engine ignores.
struct LabelledScan {
  Points points;
  std::vector<std::uint32_t> labels;
};

// Thrown for input the engine cannot use (wrong sizes, non-finite values, unreadable files, bad config).
// The message always says what is wrong and, for files, which file.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Points per scan: the default of the server's `max_points` setting, and the cap of the scan file readers
// (sglc/scan_file.hpp), which refuse a file declaring more points from its size or header, before reading it.
inline constexpr std::size_t kMaxScanPoints = 2'000'000;

// Checks a scan before sending or any work, by the rules a server applies (the wire codec's decodeScan calls it):
// at least one point ("scan is empty"), one label per point or none at all (an unlabelled scan, which the
// labeller labels), and finite coordinates. Throws InputError naming the first offending point.
void validateScan(const LabelledScan& scan);

}  // namespace sglc
