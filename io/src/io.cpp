#include "sglc/io.hpp"

#include "file_bytes.hpp"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <optional>
#include <sstream>

namespace sglc {
using detail::readAll;
using detail::writeAll;

Points readKittiBin(const std::string& path, std::vector<float>* intensities) {
  const detail::RegularFile file(path);
  if (file.size() % 16 != 0)
    throw InputError(path + ": size " + std::to_string(file.size()) +
                     " bytes is not a multiple of 16 (4 float32 per point); truncated file?");
  detail::checkScanPoints(path, file.size() / 16, "16 bytes each in the file");
  const auto data = file.readAll();
  const std::size_t n = data.size() / 16;
  Points points(n);
  if (intensities) intensities->resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    float v[4];
    std::memcpy(v, data.data() + i * 16, 16);
    if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
      throw InputError(path + ": point " + std::to_string(i) + " has a non-finite coordinate");
    points[i] = Vec3f(v[0], v[1], v[2]);
    if (intensities) (*intensities)[i] = v[3];
  }
  return points;
}

std::vector<float> readPointTimes(const std::string& path, std::size_t points) {
  const detail::RegularFile file(path);
  if (file.size() != std::uint64_t{points} * 4)
    throw InputError(path + ": " + std::to_string(file.size()) + " bytes, but its scan has " + std::to_string(points) +
                     " points (4 bytes, one float32, each)");
  const auto data = file.readAll();
  std::vector<float> times(points);
  std::memcpy(times.data(), data.data(), points * 4);
  for (std::size_t i = 0; i < points; ++i)
    if (!std::isfinite(times[i]) || std::abs(times[i]) > 1.0f)
      throw InputError(path + ": point " + std::to_string(i) + "'s time " + std::to_string(times[i]) +
                       " s is not within 1 s of the scan's stamp");
  return times;
}

void writePointTimes(const std::string& path, const std::vector<float>& times) {
  writeAll(path, times.data(), times.size() * sizeof(float));
}

std::vector<std::uint32_t> readLabels(const std::string& path, std::size_t points) {
  const detail::RegularFile file(path);
  if (file.size() > std::uint64_t{kMaxScanPoints} * 4)
    throw InputError(path + ": " + std::to_string(file.size()) + " bytes, more than the labels of " +
                     std::to_string(kMaxScanPoints) + " points (the most a scan may have)");
  const auto data = file.readAll();
  std::size_t width = 4;
  if (points > 0) {
    // One label per point, 1, 2 or 4 bytes wide (nuScenes-lidarseg uint8, uint16 sets, SemanticKITTI uint32).
    if (data.size() % points != 0 ||
        (data.size() / points != 1 && data.size() / points != 2 && data.size() / points != 4))
      throw InputError(path + ": " + std::to_string(data.size()) + " bytes for " + std::to_string(points) +
                       " points: not 1, 2 or 4 bytes per point");
    width = data.size() / points;
  } else if (data.size() % 4 != 0) {
    throw InputError(path + ": size " + std::to_string(data.size()) +
                     " bytes is not a multiple of 4 (uint32 per point); truncated file?");
  }
  std::vector<std::uint32_t> labels(data.size() / width);
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
  for (std::size_t i = 0; i < labels.size(); ++i) {  // little-endian, whatever the width
    std::uint32_t v = 0;
    for (std::size_t b = 0; b < width; ++b) v |= static_cast<std::uint32_t>(bytes[i * width + b]) << (8 * b);
    labels[i] = v;
  }
  return labels;
}

namespace {
// Calls f(line, "path:line") for each line that is not blank or a '#' comment, until f returns false.
template <typename F>
void forEachDataLine(const std::string& path, F&& f) {
  detail::requireRegularFile(path);  // a FIFO would block the open
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open (" + std::strerror(errno) + ")");
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
    if (!f(line, path + ":" + std::to_string(line_no))) return;
  }
}

Mat4d parseRow12(std::istringstream& ss, const std::string& where) {
  Mat4d T = Mat4d::Identity();
  for (int k = 0; k < 12; ++k) {
    double v;
    if (!(ss >> v)) throw InputError(where + ": expected 12 numbers (row-major 3x4)");
    if (!std::isfinite(v)) throw InputError(where + ": non-finite value");
    T(k / 4, k % 4) = v;
  }
  std::string extra;
  if (ss >> extra) throw InputError(where + ": more than 12 numbers");
  return T;
}
}  // namespace

std::vector<Mat4d> readPoses(const std::string& path) {
  std::vector<Mat4d> poses;
  forEachDataLine(path, [&](const std::string& line, const std::string& where) {
    std::istringstream ss(line);
    poses.push_back(parseRow12(ss, where));
    return true;
  });
  return poses;
}

std::vector<double> readStamps(const std::string& path) {
  std::vector<double> stamps;
  forEachDataLine(path, [&](const std::string& line, const std::string& where) {
    std::istringstream ss(line);
    double v;
    std::string extra;
    if (!(ss >> v) || (ss >> extra) || !std::isfinite(v))
      throw InputError(where + ": expected one timestamp in seconds");
    stamps.push_back(v);
    return true;
  });
  return stamps;
}

int posesColumns(const std::string& path) {
  int columns = 0;
  forEachDataLine(path, [&](const std::string& line, const std::string&) {
    std::istringstream ss(line);
    std::string token;
    while (ss >> token) ++columns;
    return false;
  });
  return columns;
}

std::vector<StampedPose> readTumPoses(const std::string& path) {
  std::vector<StampedPose> poses;
  forEachDataLine(path, [&](const std::string& line, const std::string& where) {
    std::istringstream ss(line);
    double v[8];
    for (double& x : v)
      if (!(ss >> x) || !std::isfinite(x))
        throw InputError(where + ": expected 8 finite numbers (t tx ty tz qx qy qz qw)");
    std::string extra;
    if (ss >> extra) throw InputError(where + ": more than 8 numbers (TUM: t tx ty tz qx qy qz qw)");
    Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    if (std::abs(q.norm() - 1.0) > 1e-3)
      throw InputError(where + ": quaternion norm " + std::to_string(q.norm()) + " is not 1");
    StampedPose p;
    p.stamp = v[0];
    p.pose.topLeftCorner<3, 3>() = q.normalized().toRotationMatrix();
    p.pose.topRightCorner<3, 1>() = Eigen::Vector3d(v[1], v[2], v[3]);
    poses.push_back(p);
    return true;
  });
  return poses;
}

Mat4d readCalibTr(const std::string& path) {
  std::optional<Mat4d> tr;
  forEachDataLine(path, [&](const std::string& line, const std::string& where) {
    if (line.rfind("Tr:", 0) != 0) return true;
    std::istringstream ss(line.substr(3));
    tr = parseRow12(ss, where);
    return false;
  });
  if (!tr) throw InputError(path + ": no 'Tr:' line (velodyne -> camera calibration)");
  return *tr;
}

void writeKittiBin(const std::string& path, const Points& points, const std::vector<float>& intensities) {
  if (!intensities.empty() && intensities.size() != points.size())
    throw InputError(path + ": " + std::to_string(intensities.size()) + " intensities for " +
                     std::to_string(points.size()) + " points");
  std::vector<float> data(points.size() * 4);
  for (std::size_t i = 0; i < points.size(); ++i) {
    data[i * 4 + 0] = points[i].x();
    data[i * 4 + 1] = points[i].y();
    data[i * 4 + 2] = points[i].z();
    data[i * 4 + 3] = intensities.empty() ? 0.0f : intensities[i];
  }
  writeAll(path, data.data(), data.size() * sizeof(float));
}

void writeLabels(const std::string& path, const std::vector<std::uint32_t>& labels) {
  writeAll(path, labels.data(), labels.size() * sizeof(std::uint32_t));
}

void writePoses(const std::string& path, const std::vector<Mat4d>& poses) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) throw InputError(path + ": cannot create (" + std::strerror(errno) + ")");
  char buf[64];
  for (const auto& T : poses) {
    for (int k = 0; k < 12; ++k) {
      std::snprintf(buf, sizeof(buf), "%.9e", T(k / 4, k % 4));
      out << buf << (k == 11 ? '\n' : ' ');
    }
  }
  if (!out) throw InputError(path + ": write failed");
}

void writeTumPoses(const std::string& path, const std::vector<StampedPose>& poses) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) throw InputError(path + ": cannot create (" + std::strerror(errno) + ")");
  for (const auto& p : poses) {
    const Eigen::Quaterniond q(Eigen::Matrix3d(p.pose.topLeftCorner<3, 3>()));
    const Eigen::Vector3d t = p.pose.topRightCorner<3, 1>();
    out << std::fixed << std::setprecision(9) << p.stamp << std::scientific;
    for (double v : {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()}) out << ' ' << v;
    out << '\n';
  }
  if (!out) throw InputError(path + ": write failed");
}

}  // namespace sglc
