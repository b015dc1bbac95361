// One scan from a file of any supported format, chosen by the file's extension:
//
//   .bin  KITTI velodyne: float32 x, y, z, reflectance per point, little-endian
//   .npy  NumPy (N, 3+) float32/float64 array (sglc/npy.hpp)
//   .pcd  PCL point cloud, ascii / binary / binary_compressed (sglc/pcl_cloud.hpp)
//   .ply  PLY point cloud, ascii / binary
//
// Labels come from `label_path` when it is given: `.label` (1, 2 or 4 bytes per point, chosen by size) or
// `.npy` (any integer type). Without it, a PCD or PLY file's `label_field` field ("label" in PointXYZL) is
// used when present; otherwise the scan is unlabelled (the engine's labeller labels it). Points and labels
// are checked against each other and for finite coordinates; every failure throws InputError naming the file,
// an unknown extension "unsupported format: ..." with the supported ones.
//
// Limits, checked before the data is read: a scan file must be a regular file (a FIFO, device or directory is
// refused, never waited on); it may hold at most kMaxScanPoints points (2,000,000, the server's default
// max_points), judged from the file size (.bin), the header's shape (.npy), POINTS (PCD) or the vertex count
// (PLY); and it may be at most kMaxScanFileBytes long (256 bytes per point of the cap: 512 MB).
#pragma once

#include <cstdint>
#include <string>

#include "sglc/types.hpp"

namespace sglc {

inline constexpr const char* kScanFormats = ".bin (KITTI float32 x y z r), .pcd, .ply, .npy (N x 3+ float)";
inline constexpr std::uint64_t kMaxScanFileBytes = std::uint64_t{kMaxScanPoints} * 256;
inline constexpr const char* kLabelFormats = ".label (uint8/16/32 per point), .npy (integer)";

LabelledScan readScan(const std::string& scan_path, const std::string& label_path,
                      const std::string& label_field = "label");

// True when `path`'s extension is a scan format readScan reads.
bool isScanFile(const std::string& path);

}  // namespace sglc
