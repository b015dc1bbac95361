// What `sglc ingest` sends: the frames of a sequence directory, or the keyframes of a bag's drive.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sglc/bag_drive.hpp"
#include "sglc/types.hpp"

namespace sglc::cli {

struct IngestFrame {
  std::string name;         // shown to the user ("000720", or the cloud's index on its topic)
  std::int64_t number = 0;  // the scan's seq in its session
  std::optional<double> stamp;
  std::optional<Mat4d> pose;
};

class IngestSource {
 public:
  virtual ~IngestSource() = default;
  virtual const std::vector<IngestFrame>& frames() const = 0;
  virtual LabelledScan scan(std::size_t i) = 0;
  virtual const std::string& name() const = 0;  // the default session name
};

struct SourceOptions {
  std::string path, frames, label_field = "label";
  int every = 1;
  std::string poses, poses_frame = "auto";  // sequence directories
  BagDriveOptions bag;  // bags: topics, keyframes; bag.deskew also applies to directories with point_times/
};

// A bag (sglc::isBag) or a sequence directory; prints notes and warnings about the poses to stderr.
std::unique_ptr<IngestSource> openSource(const SourceOptions& o);

}  // namespace sglc::cli
