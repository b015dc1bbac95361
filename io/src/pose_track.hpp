// Poses over time, as a bag gives them: a stamped track interpolated between samples, and a tf tree (static
// and dynamic edges) to look one frame up in another.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "sglc/types.hpp"

namespace sglc {

class PoseTrack {
 public:
  void add(std::int64_t stamp_ns, const Mat4d& T) { samples_.push_back({stamp_ns, T}); }
  void sort();  // before at(); duplicates of a stamp keep the first
  bool empty() const { return samples_.empty(); }
  // The pose at t: interpolated between the samples around it (linear position, slerp rotation); the end sample
  // within `slack_ns` beyond either end; nullopt further out.
  std::optional<Mat4d> at(std::int64_t t, std::int64_t slack_ns) const;

 private:
  std::vector<std::pair<std::int64_t, Mat4d>> samples_;
};

class TfTree {
 public:
  void addStatic(const std::string& parent, const std::string& child, const Mat4d& T);
  void addDynamic(const std::string& parent, const std::string& child, std::int64_t stamp_ns, const Mat4d& T);
  void sort();
  bool has(const std::string& frame) const;
  // The pose of `frame` in `ancestor` at t, composed up the tree; nullopt when a dynamic edge on the way has no
  // pose at t. Throws InputError when `ancestor` is not above `frame` (naming the chain there is).
  std::optional<Mat4d> lookup(const std::string& ancestor, const std::string& frame, std::int64_t t,
                              std::int64_t slack_ns) const;

 private:
  struct Edge {
    std::string parent;
    bool fixed = false;
    Mat4d T = Mat4d::Identity();
    PoseTrack track;
  };
  std::map<std::string, Edge> up_;  // child -> its edge to the parent
};

}  // namespace sglc
