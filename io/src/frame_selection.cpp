#include "sglc/frame_selection.hpp"

#include <charconv>

namespace sglc {
namespace {

std::string_view trim(std::string_view v) {
  while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.remove_prefix(1);
  while (!v.empty() && (v.back() == ' ' || v.back() == '\t')) v.remove_suffix(1);
  return v;
}

std::vector<std::string_view> split(std::string_view text, char sep) {
  std::vector<std::string_view> parts;
  for (std::size_t start = 0;;) {
    const std::size_t at = text.find(sep, start);
    parts.push_back(trim(text.substr(start, at == std::string_view::npos ? std::string_view::npos : at - start)));
    if (at == std::string_view::npos) return parts;
    start = at + 1;
  }
}

constexpr std::int64_t kMaxFrame = 1'000'000'000'000;  // 13 digits: any real sequence, no overflow below

}  // namespace

FrameSelection FrameSelection::parse(std::string_view spec) {
  FrameSelection s;
  s.text_ = std::string(trim(spec));
  if (s.text_.empty()) return s;
  for (const auto item_text : split(s.text_, ',')) {
    const std::string what = "frame selection item '" + std::string(item_text) + "'";
    const auto parts = split(item_text, ':');
    if (item_text.empty() || parts.size() > 3) throw InputError(what + ": expected a, a:b or a:b:s (b exclusive)");
    auto number = [&](std::string_view v) {
      std::int64_t x = 0;
      const auto [ptr, ec] = std::from_chars(v.data(), v.data() + v.size(), x);
      if (ec != std::errc() || ptr != v.data() + v.size() || x < 0 || x > kMaxFrame)
        throw InputError(what + ": '" + std::string(v) + "' is not a frame number (a non-negative integer)");
      return x;
    };
    Item it;
    it.text = std::string(item_text);
    if (parts.size() == 1) {
      it.first = number(parts[0]);
      it.end = it.first + 1;
    } else {
      if (!parts[0].empty()) it.first = number(parts[0]);
      if (!parts[1].empty()) it.end = number(parts[1]);
      if (parts.size() == 3) {
        if (parts[2].empty()) throw InputError(what + ": empty stride");
        it.stride = number(parts[2]);
        if (it.stride < 1) throw InputError(what + ": stride must be at least 1");
      }
      if (it.end && *it.end <= it.first)
        throw InputError(what + ": the end must be greater than the start (b is exclusive)");
    }
    if (!s.items_.empty()) {
      const Item& prev = s.items_.back();
      if (!prev.end || it.first < *prev.end)
        throw InputError(what + ": items must be ascending and must not overlap (it starts at " +
                         std::to_string(it.first) + ", before the end of '" + prev.text + "')");
    }
    s.items_.push_back(std::move(it));
  }
  return s;
}

bool FrameSelection::contains(std::int64_t frame) const {
  if (items_.empty()) return true;
  for (const auto& it : items_)
    if (frame >= it.first && (!it.end || frame < *it.end) && (frame - it.first) % it.stride == 0) return true;
  return false;
}

std::vector<int> FrameSelection::frames(int num_frames) const {
  std::vector<int> out;
  if (items_.empty()) {
    for (int i = 0; i < num_frames; ++i) out.push_back(i);
    return out;
  }
  for (const auto& it : items_) {
    const std::int64_t end = it.end.value_or(num_frames);
    if (end > num_frames || it.first >= num_frames)
      throw InputError("frame selection item '" + it.text + "': the sequence has only " + std::to_string(num_frames) +
                       " frames (0.." + std::to_string(num_frames - 1) + ")");
    for (std::int64_t i = it.first; i < end; i += it.stride) out.push_back(static_cast<int>(i));
  }
  return out;
}

}  // namespace sglc
