// A SemanticKITTI-layout sequence directory, as `sglc ingest` reads it:
//
//   DIR/velodyne/NNNNNN.EXT    scans, all in one format: .bin (KITTI), .pcd, .ply or .npy (sglc/scan_file.hpp)
//   DIR/labels/NNNNNN.label    labels (.label: uint8/16/32 per point, or .npy); all present or all absent. A
//                              PCD/PLY scan with a label field carries its own labels (no labels/ needed)
//   DIR/poses.txt              optional: odometry poses in frame order, KITTI (3x4 row-major, 12 numbers per
//                              line) or TUM (t tx ty tz qx qy qz qw, 8 numbers), told apart by the first line
//   DIR/times.txt              optional: one timestamp in seconds per line, in frame order (a TUM poses.txt
//                              gives the stamps when there is no times.txt)
//   DIR/point_times/NNNNNN.bin optional: float32 per point, seconds after the scan's stamp when it was measured
//                              (the simulator writes them with --motion-distortion); what de-skew needs
//   DIR/calib.txt              optional: KITTI calibration; its "Tr:" line (velodyne -> left camera) turns
//                              KITTI camera-frame poses into LiDAR poses (below)
//
// "In frame order" means line i belongs to frame number i (the KITTI convention, which needs at least
// highest-frame-number + 1 lines). A file with exactly one line per .bin present is also accepted and then
// read by position (line k belongs to the k-th frame in ascending order), for directories that hold a
// subset of a sequence with a matching subset of poses. Anything else is an error.
//
// Frames of the poses. KITTI's own poses.txt is the left camera's trajectory, not the LiDAR's. With
// PosesFrame::kAuto, a KITTI-format (12-column) poses file next to a calib.txt is taken as camera poses and
// turned into LiDAR poses, T_lidar = Tr^-1 T_cam Tr (the simulator's calib.txt holds Tr = identity, so its
// LiDAR-frame poses pass unchanged); a TUM file, or a KITTI file without calib.txt, is taken as LiDAR poses.
// kLidar takes the file as it is; kCamera applies Tr and needs calib.txt. Poses whose first metre of travel
// goes mostly along the sensor's z (a ground robot's LiDAR moves along its x-y plane; a camera's forward axis
// is z) get a warning in Sequence::warnings.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "sglc/frame_selection.hpp"
#include "sglc/types.hpp"

namespace sglc {

struct SequenceFrame {
  std::string name;         // file stem, e.g. "000720"
  std::int64_t number = 0;  // 720
  std::string scan_path;    // any format of sglc/scan_file.hpp
  std::string label_path;
  std::string point_times_path;  // DIR/point_times/NAME.bin when there (sglc/io.hpp readPointTimes), else ""
  std::optional<Mat4d> pose;
  std::optional<double> stamp;
};

enum class PosesFrame { kAuto, kLidar, kCamera };
// "auto", "lidar" or "camera"; throws InputError otherwise.
PosesFrame parsePosesFrame(const std::string& text);

struct PoseOptions {
  std::string file;  // odometry file (KITTI or TUM) instead of DIR/poses.txt; same indexing rule
  PosesFrame frame = PosesFrame::kAuto;
};

struct Sequence {
  std::string dir;
  std::string name;                   // the directory's base name ("00" for .../sequences/00/)
  std::vector<SequenceFrame> frames;  // selected frames, ascending
  std::size_t frames_in_dir = 0;      // before selection
  bool has_poses = false;
  bool has_stamps = false;
  std::string poses_path;             // the poses file read ("" when none)
  bool poses_from_camera = false;     // calib.txt's Tr was applied
  std::vector<std::string> warnings;  // for the user: the caller prints them
};

// Lists the selected frames: those whose numbers `selection` contains, then every `every`-th of them (the first, the
// every+1-th, ...). Throws InputError when the directory is not a sequence, `every` < 1, nothing is
// selected, a selected scan has no label file, the poses file / times.txt / calib.txt cannot be read or do not
// match. Scans themselves are not read.
Sequence openSequence(const std::string& dir, const FrameSelection& selection = {}, int every = 1,
                      const PoseOptions& poses = {});

}  // namespace sglc
