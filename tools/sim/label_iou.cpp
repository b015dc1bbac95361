#include "sim/label_iou.hpp"

#include <stdexcept>

namespace sglc::sim {
namespace {

// Raw class id (low 16 bits, < 260) -> evaluation index, built once at compile time.
constexpr std::array<std::int8_t, 260> buildEvalLookup() {
  std::array<std::int8_t, 260> t{};
  for (auto& v : t) v = -1;
  for (int k = 0; k < kEvalClasses; ++k) t[kEvalClassTable[k].id] = static_cast<std::int8_t>(k);
  // SemanticKITTI's learning map folds the moving classes onto their static ones for single-scan scoring.
  for (std::uint32_t c = 252; c <= 259; ++c) t[c] = t[label::staticOf(c)];
  t[13] = t[20];  // bus
  t[16] = t[20];  // on-rails
  return t;
}
constexpr std::array<std::int8_t, 260> kEvalLookup = buildEvalLookup();

}  // namespace

int evalClassIndex(std::uint32_t raw_label) {
  const std::uint32_t cls = raw_label & 0xFFFFu;
  return cls < kEvalLookup.size() ? kEvalLookup[cls] : -1;
}

void LabelIouCounts::add(const std::vector<std::uint32_t>& truth, const std::vector<std::uint32_t>& predicted) {
  if (truth.size() != predicted.size()) throw std::invalid_argument("LabelIouCounts: label vectors differ in size");
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const int t = evalClassIndex(truth[i]);
    if (t < 0) continue;
    const int p = evalClassIndex(predicted[i]);
    if (p == t) {
      ++tp_[t];
      continue;
    }
    ++fn_[t];
    if (p >= 0) ++fp_[p];
  }
}

void LabelIouCounts::addExact(const std::vector<std::uint32_t>& labels) {
  for (const std::uint32_t raw : labels) {
    const int t = evalClassIndex(raw);
    if (t >= 0) ++tp_[t];
  }
}

void LabelIouCounts::merge(const LabelIouCounts& other) {
  for (int k = 0; k < kEvalClasses; ++k) {
    tp_[k] += other.tp_[k];
    fp_[k] += other.fp_[k];
    fn_[k] += other.fn_[k];
  }
}

double LabelIouCounts::iou(int k) const {
  const std::uint64_t u = tp_[k] + fp_[k] + fn_[k];
  return u == 0 ? 0.0 : static_cast<double>(tp_[k]) / static_cast<double>(u);
}

double LabelIouCounts::meanIou() const {
  double sum = 0.0;
  int n = 0;
  for (int k = 0; k < kEvalClasses; ++k)
    if (present(k)) {
      sum += iou(k);
      ++n;
    }
  return n == 0 ? 1.0 : sum / n;
}

}  // namespace sglc::sim
