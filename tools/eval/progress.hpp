// Feedback and read-ahead for the evaluation's frame loops: a one-line progress bar with rate and ETA, and a
// loader that renders or reads frames ahead of use on background threads, in order.
#pragma once

#include <chrono>
#include <cstddef>
#include <deque>
#include <future>
#include <string>
#include <utility>
#include <vector>

#include "source.hpp"

namespace sglc::eval {

// On stderr: redrawn in place on a terminal, a line per 10 % otherwise (logs stay short).
class Progress {
 public:
  Progress(std::string label, std::size_t total);
  void step(std::size_t done);

 private:
  std::string label_;
  std::size_t total_;
  bool tty_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  double shown_ = -1;
  std::size_t tenth_ = 0;
};

// Loads up to `ahead` frames ahead; next() hands them out in the order given.
class Prefetch {
 public:
  Prefetch(const FrameSource& source, std::vector<int> frames, int ahead);
  bool done() const { return next_ == frames_.size() && pending_.empty(); }
  std::pair<int, LabelledScan> next();

 private:
  const FrameSource& source_;
  std::vector<int> frames_;
  int ahead_;
  std::size_t next_ = 0;
  std::deque<std::pair<int, std::future<LabelledScan>>> pending_;
};

// Seconds since t0.
double secondsSince(std::chrono::steady_clock::time_point t0);

}  // namespace sglc::eval
