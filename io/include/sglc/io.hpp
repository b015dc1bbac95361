// Plain file readers and writers for the KITTI / SemanticKITTI formats. Every failure throws InputError
// with the file name and what is wrong.
#pragma once

#include <string>
#include <vector>

#include "sglc/scan_file.hpp"
#include "sglc/types.hpp"

namespace sglc {

// KITTI velodyne .bin: float32 little-endian x, y, z, reflectance per point.
Points readKittiBin(const std::string& path, std::vector<float>* intensities = nullptr);
// A .label file: uint32 per point (SemanticKITTI); given the scan's point count, also 1 or 2 bytes per point
// (nuScenes-lidarseg's uint8), chosen by the file's size. Little-endian.
std::vector<std::uint32_t> readLabels(const std::string& path, std::size_t points = 0);
// A point_times/NNNNNN.bin file: float32 little-endian per point of its scan (`points` of them), the seconds
// after the scan's stamp at which each point was measured (what de-skew needs; sglc/deskew.hpp).
std::vector<float> readPointTimes(const std::string& path, std::size_t points);
void writePointTimes(const std::string& path, const std::vector<float>& times);
// Poses, stamps and calibration files are read line by line: blank lines and lines starting with '#' are
// skipped, errors name the file and line.
// KITTI poses file: one row-major 3x4 matrix per line (12 numbers).
std::vector<Mat4d> readPoses(const std::string& path);
// A times.txt: one finite timestamp in seconds per line.
std::vector<double> readStamps(const std::string& path);
// A TUM trajectory file (evo, TUM RGB-D): "timestamp tx ty tz qx qy qz qw" per line, '#' comments. The
// quaternion is normalised (refused when its norm is far from 1).
struct StampedPose {
  double stamp = 0;
  Mat4d pose = Mat4d::Identity();
};
std::vector<StampedPose> readTumPoses(const std::string& path);
// How many numbers the first data line of a poses file holds: 12 for KITTI, 8 for TUM (0 when empty).
int posesColumns(const std::string& path);
// The "Tr:" line of a KITTI calib.txt (velodyne -> cam0), as a 4x4 matrix.
Mat4d readCalibTr(const std::string& path);

void writeKittiBin(const std::string& path, const Points& points, const std::vector<float>& intensities);
void writeLabels(const std::string& path, const std::vector<std::uint32_t>& labels);
void writePoses(const std::string& path, const std::vector<Mat4d>& poses);
void writeTumPoses(const std::string& path, const std::vector<StampedPose>& poses);

}  // namespace sglc
