// A frame's points on its beams x columns grid, for the neighbour lookups of both label-noise models.
#pragma once

#include <cstddef>
#include <vector>

#include "sim/simulator.hpp"

namespace sglc::sim {

struct PointImage {
  int beams = 0, columns = 0;
  // Spinning sensors: the last column neighbours the first (a full turn). A forward-looking field of view (the
  // rosette's pseudo image) has two separate edges.
  bool wrap = true;
  std::vector<int> index;  // point per pixel, -1 where none; of several points in one cell, the last

  PointImage(const Frame& frame, int beams_, int columns_, bool wrap_)
      : beams(beams_), columns(columns_), wrap(wrap_), index(static_cast<std::size_t>(beams_) * columns_, -1) {
    for (std::size_t i = 0; i < frame.beam.size(); ++i)
      index[static_cast<std::size_t>(frame.beam[i]) * columns + frame.column[i]] = static_cast<int>(i);
  }
  // The point at beam b, column c, or -1 (no point, or outside the image).
  int at(int b, int c) const {
    if (b < 0 || b >= beams) return -1;
    if (wrap)
      c = (c % columns + columns) % columns;
    else if (c < 0 || c >= columns)
      return -1;
    return index[static_cast<std::size_t>(b) * columns + c];
  }
};

}  // namespace sglc::sim
