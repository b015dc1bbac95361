// The one frame-selection grammar of every command line (sglc ingest, sglc-sim, sglc-eval):
//
//   ""           every frame
//   "a"          frame a
//   "a:b"        frames a .. b-1 (b exclusive); "a:" to the end, ":b" from 0
//   "a:b:s"      every s-th frame from a up to b-1 ("::3": every third frame)
//   "x,y,..."    several items, ascending and not overlapping ("0:300,4300:4541", "52,4501")
//
// Spaces around items and numbers are ignored. Anything else throws InputError naming the item.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "sglc/types.hpp"

namespace sglc {

class FrameSelection {
 public:
  FrameSelection() = default;  // every frame
  static FrameSelection parse(std::string_view spec);

  bool all() const { return items_.empty(); }
  // Whether frame number `frame` is selected (an open end reaches any frame).
  bool contains(std::int64_t frame) const;
  // The selected frames of a sequence of `num_frames` frames (0 .. num_frames-1), ascending. Throws when an item
  // with a closed end reaches beyond the sequence (the message says how many frames there are).
  std::vector<int> frames(int num_frames) const;
  // The text it was parsed from.
  const std::string& text() const { return text_; }

 private:
  struct Item {
    std::int64_t first = 0;
    std::optional<std::int64_t> end;  // exclusive; open when absent
    std::int64_t stride = 1;
    std::string text;
  };
  std::vector<Item> items_;
  std::string text_;
};

}  // namespace sglc
