#include "progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace sglc::eval {

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Progress::Progress(std::string label, std::size_t total)
    : label_(std::move(label)), total_(total), tty_(isatty(2) != 0) {}

void Progress::step(std::size_t done) {
  const double t = secondsSince(start_);
  const bool last = done == total_;
  const std::size_t total = std::max<std::size_t>(total_, 1);
  if (tty_ ? (t - shown_ < 0.25 && !last) : (done * 10 / total == tenth_ && !last)) return;
  shown_ = t;
  tenth_ = done * 10 / total;
  const double rate = t > 0 ? static_cast<double>(done) / t : 0;
  const double eta = rate > 0 ? static_cast<double>(total_ - done) / rate : 0;
  const int width = 30;
  const int fill = static_cast<int>(width * static_cast<double>(done) / static_cast<double>(total));
  std::ostringstream line;
  line << label_ << " [" << std::string(fill, '#') << std::string(width - fill, '.') << "] " << done << "/" << total_
       << "  " << std::fixed << std::setprecision(1) << rate << "/s  ETA " << static_cast<int>(eta) / 60 << "m"
       << std::setw(2) << std::setfill('0') << static_cast<int>(eta) % 60 << "s";
  std::cerr << (tty_ ? "\r" : "") << line.str() << (tty_ && !last ? "" : "\n") << std::flush;
}

Prefetch::Prefetch(const FrameSource& source, std::vector<int> frames, int ahead)
    : source_(source), frames_(std::move(frames)), ahead_(std::max(1, ahead)) {}

std::pair<int, LabelledScan> Prefetch::next() {
  while (pending_.size() < static_cast<std::size_t>(ahead_) && next_ < frames_.size()) {
    const int f = frames_[next_++];
    pending_.emplace_back(f, std::async(std::launch::async, [this, f] { return source_.scan(f); }));
  }
  auto [f, fut] = std::move(pending_.front());
  pending_.pop_front();
  return {f, fut.get()};
}

}  // namespace sglc::eval
