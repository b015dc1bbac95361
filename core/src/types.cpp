#include "sglc/types.hpp"

#include <string>

namespace sglc {

void validateScan(const LabelledScan& scan) {
  if (scan.points.empty()) throw InputError("scan is empty");
  if (!scan.labels.empty() && scan.points.size() != scan.labels.size())
    throw InputError("scan has " + std::to_string(scan.points.size()) + " points but " +
                     std::to_string(scan.labels.size()) + " labels");
  for (std::size_t i = 0; i < scan.points.size(); ++i)
    if (!scan.points[i].allFinite())
      throw InputError("scan point " + std::to_string(i) + " has a non-finite coordinate (NaN or inf)");
}

}  // namespace sglc
