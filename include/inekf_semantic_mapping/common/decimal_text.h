// Number-to-text for large text outputs (the PLY map export writes seven numbers for each of
// hundreds of thousands of voxels): the same characters as printf's "%.4f" and "%u", without
// printf's format parsing and locale per number.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>

namespace inekf_semantic_mapping {
namespace common {

// Writes `value` in decimal at `out`; returns the end (no terminating NUL). Needs 20 chars.
inline char* appendUnsigned(char* out, std::uint64_t value) {
  char digits[20];
  int n = 0;
  do {
    digits[n++] = static_cast<char>('0' + value % 10);
    value /= 10;
  } while (value != 0);
  while (n > 0) *out++ = digits[--n];
  return out;
}

// Writes `value` as printf("%.4f") would; returns the end (no terminating NUL). Needs 32 chars
// for |value| < 1e15 (larger values, NaN and infinities go to snprintf, needing up to 320).
// printf rounds the exact binary value to the nearest 4-decimal figure; value * 1e4 carries a
// relative error of about 1e-16, so the integer rounding agrees unless the fraction is within
// 1e-6 of a tie, and those rare values also go to snprintf.
inline char* appendFixed4(char* out, double value) {
  const double scaled = std::abs(value) * 1e4;
  if (!(scaled < 1e15) || std::abs(scaled - std::floor(scaled) - 0.5) < 1e-6) {
    return out + std::snprintf(out, 320, "%.4f", value);
  }
  const auto units = static_cast<std::uint64_t>(std::llround(scaled));
  if (std::signbit(value)) *out++ = '-';  // printf writes -0.0000 for small negatives too
  out = appendUnsigned(out, units / 10000);
  *out++ = '.';
  const auto fraction = static_cast<unsigned int>(units % 10000);
  *out++ = static_cast<char>('0' + fraction / 1000);
  *out++ = static_cast<char>('0' + fraction / 100 % 10);
  *out++ = static_cast<char>('0' + fraction / 10 % 10);
  *out++ = static_cast<char>('0' + fraction % 10);
  return out;
}

}  // namespace common
}  // namespace inekf_semantic_mapping
