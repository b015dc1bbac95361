// Reads ROS message fields from bytes from outside: ROS 2's CDR (XCDR1: a 4-byte encapsulation header giving
// the byte order, primitives aligned to their size from the end of that header, strings with a trailing NUL)
// or ROS 1's serialisation (little-endian, packed, strings without NUL). Every read is bounds-checked and
// throws InputError naming the message and field.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>

#include "sglc/bag.hpp"
#include "sglc/types.hpp"

namespace sglc {

class RosReader {
 public:
  RosReader(const std::uint8_t* data, std::size_t size, MessageEncoding encoding, std::string what)
      : p_(data), n_(size), cdr_(encoding == MessageEncoding::kCdr), what_(std::move(what)) {
    if (!cdr_) return;
    if (n_ < 4) fail("CDR encapsulation header", 4);
    if (p_[0] != 0 || p_[1] > 1)
      throw InputError(what_ + ": unknown CDR encapsulation " + std::to_string(p_[0]) + " " + std::to_string(p_[1]) +
                       " (expected plain CDR, big- or little-endian)");
    big_ = p_[1] == 0;
    p_ += 4;
    n_ -= 4;
  }

  const std::string& what() const { return what_; }
  bool ros1() const { return !cdr_; }

  template <typename T>
  T get(const char* field) {
    align(sizeof(T));
    if (sizeof(T) > n_ - at_) fail(field, sizeof(T));
    std::uint8_t b[sizeof(T)];
    std::memcpy(b, p_ + at_, sizeof(T));
    if (big_) std::reverse(b, b + sizeof(T));
    at_ += sizeof(T);
    T v;
    std::memcpy(&v, b, sizeof(T));
    return v;
  }
  std::string string(const char* field) {
    const auto len = get<std::uint32_t>(field);
    if (len > n_ - at_) fail(field, len);
    std::size_t used = len;
    if (cdr_ && used > 0 && p_[at_ + used - 1] == 0) --used;  // CDR counts the trailing NUL
    std::string s(reinterpret_cast<const char*>(p_ + at_), used);
    at_ += len;
    return s;
  }
  // A sequence's element count, checked against the bytes left (each element at least `min_bytes`).
  std::uint32_t count(const char* field, std::size_t min_bytes) {
    const auto k = get<std::uint32_t>(field);
    if (min_bytes && k > (n_ - at_) / min_bytes) fail(field, std::size_t(k) * min_bytes);
    return k;
  }
  // A byte sequence (uint8[]): its bytes, in place.
  const std::uint8_t* bytes(const char* field, std::size_t* size) {
    const auto k = get<std::uint32_t>(field);
    if (k > n_ - at_) fail(field, k);
    const std::uint8_t* out = p_ + at_;
    at_ += k;
    *size = k;
    return out;
  }
  // A ROS header: ROS 1's seq, then the stamp and frame id. Returns the stamp in ns.
  std::int64_t header(std::string* frame_id) {
    if (!cdr_) get<std::uint32_t>("header.seq");
    const auto sec = cdr_ ? std::int64_t(get<std::int32_t>("header.stamp.sec"))
                          : std::int64_t(get<std::uint32_t>("header.stamp.sec"));
    const auto nsec = get<std::uint32_t>("header.stamp.nanosec");
    if (nsec >= 1000000000u)
      throw InputError(what_ + ": header.stamp.nanosec " + std::to_string(nsec) + " is not below 1e9");
    *frame_id = string("header.frame_id");
    return sec * 1000000000LL + nsec;
  }

 private:
  void align(std::size_t k) {
    if (!cdr_) return;
    const std::size_t pad = (k - at_ % k) % k;
    if (pad > n_ - at_) fail("alignment", pad);
    at_ += pad;
  }
  [[noreturn]] void fail(const char* field, std::size_t need) const {
    throw InputError(what_ + ": " + field + " needs " + std::to_string(need) + " bytes at offset " +
                     std::to_string(at_) + ", only " + std::to_string(n_ - std::min(at_, n_)) +
                     " remain (truncated, or not the type its topic says)");
  }

  const std::uint8_t* p_;
  std::size_t n_;
  std::size_t at_ = 0;
  bool cdr_;
  bool big_ = false;
  std::string what_;
};

}  // namespace sglc
