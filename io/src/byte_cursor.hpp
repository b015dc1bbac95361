// Bounds-checked little-endian reads over bytes from outside (bag records): every read past the end throws
// InputError naming what was being read.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>

#include "sglc/types.hpp"

namespace sglc {

class ByteCursor {
 public:
  ByteCursor(const std::uint8_t* data, std::size_t size, std::string what)
      : p_(data), n_(size), what_(std::move(what)) {}

  std::size_t at() const { return at_; }
  std::size_t left() const { return n_ - at_; }
  const std::uint8_t* here() const { return p_ + at_; }
  const std::string& what() const { return what_; }

  void need(std::size_t k, const char* field) const {
    if (k > n_ - at_)
      throw InputError(what_ + ": " + field + " needs " + std::to_string(k) + " bytes at offset " +
                       std::to_string(at_) + ", but only " + std::to_string(n_ - at_) +
                       " remain (truncated or corrupt)");
  }
  void skip(std::size_t k, const char* field) {
    need(k, field);
    at_ += k;
  }
  template <typename T>
  T le(const char* field) {
    need(sizeof(T), field);
    T v;
    std::memcpy(&v, p_ + at_, sizeof(T));  // the machines this builds for are little-endian (checked in bag.cpp)
    at_ += sizeof(T);
    return v;
  }
  // A string with a uint32 length prefix.
  std::string str(const char* field) {
    const auto len = le<std::uint32_t>(field);
    need(len, field);
    std::string s(reinterpret_cast<const char*>(p_ + at_), len);
    at_ += len;
    return s;
  }

 private:
  const std::uint8_t* p_;
  std::size_t n_;
  std::size_t at_ = 0;
  std::string what_;
};

}  // namespace sglc
