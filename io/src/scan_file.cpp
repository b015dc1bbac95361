#include "sglc/scan_file.hpp"

#include <filesystem>

#include "sglc/io.hpp"
#include "sglc/npy.hpp"
#include "sglc/pcl_cloud.hpp"

namespace sglc {
namespace {

std::string extensionOf(const std::string& path) { return std::filesystem::path(path).extension().string(); }

std::vector<std::uint32_t> readLabelFile(const std::string& path, std::size_t points) {
  const std::string ext = extensionOf(path);
  if (ext == ".npy") return readNpyLabels(path);
  if (ext == ".label") return points > 0 ? readLabels(path, points) : readLabels(path);
  throw InputError(path + ": unsupported format: '" + ext + "' (label files: " + kLabelFormats + ")");
}

}  // namespace

bool isScanFile(const std::string& path) {
  const std::string ext = extensionOf(path);
  return ext == ".bin" || ext == ".npy" || ext == ".pcd" || ext == ".ply";
}

LabelledScan readScan(const std::string& scan_path, const std::string& label_path, const std::string& label_field) {
  const std::string ext = extensionOf(scan_path);
  LabelledScan scan;
  if (ext == ".bin") {
    scan.points = readKittiBin(scan_path);
  } else if (ext == ".npy") {
    scan.points = readNpyPoints(scan_path);
  } else if (ext == ".pcd" || ext == ".ply") {
    scan = readPclCloud(scan_path, label_field);
  } else {
    throw InputError(scan_path + ": unsupported format: '" + ext + "' (scans: " + kScanFormats + ")");
  }
  if (label_path.empty()) return scan;  // unlabelled, or the file's own labels
  scan.labels = readLabelFile(label_path, scan.points.size());
  if (scan.points.size() != scan.labels.size())
    throw InputError(label_path + ": " + std::to_string(scan.labels.size()) + " labels for " +
                     std::to_string(scan.points.size()) + " points in " + scan_path);
  return scan;
}

}  // namespace sglc
