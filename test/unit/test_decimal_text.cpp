// The PLY export's number formatting: the same text as printf's "%.4f" and "%u".
#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <random>
#include <string>

#include "inekf_semantic_mapping/common/decimal_text.h"

namespace {

using inekf_semantic_mapping::common::appendFixed4;
using inekf_semantic_mapping::common::appendUnsigned;

std::string fixed4(double value) {
  char text[400];
  return std::string(text, appendFixed4(text, value));
}

std::string printfFixed4(double value) {
  char text[400];
  std::snprintf(text, sizeof(text), "%.4f", value);
  return text;
}

TEST(DecimalText, FixedPointMatchesPrintfOnVoxelCentresAndRandomValues) {
  // Voxel centres as the map writes them: float keyToCoord of resolutions 0.05 .. 0.5 m.
  for (const double resolution : {0.05, 0.1, 0.2, 0.25, 0.5}) {
    for (int key = -40000; key <= 40000; key += 7) {
      const float centre = static_cast<float>((key + 0.5) * resolution);
      ASSERT_EQ(fixed4(centre), printfFixed4(centre)) << centre;
    }
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> wide(-1e6, 1e6), narrow(-1.0, 1.0);
  for (int i = 0; i < 200000; ++i) {
    const double a = wide(rng), b = narrow(rng);
    ASSERT_EQ(fixed4(a), printfFixed4(a)) << a;
    ASSERT_EQ(fixed4(b), printfFixed4(b)) << b;
  }
}

TEST(DecimalText, TiesSignsAndExtremesAreWrittenAsPrintfWrites) {
  for (const double value :
       {0.0, -0.0, 0.00005, -0.00005, 0.00015, 1.00025, 2.5, -0.00001, 0.99995, 9.99995,
        123456.78905, 1e15, -3e20, 1e-300, std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()}) {
    EXPECT_EQ(fixed4(value), printfFixed4(value)) << value;
  }
}

TEST(DecimalText, UnsignedIntegersIncludingZeroAndTheLargest) {
  for (const std::uint64_t value :
       {std::uint64_t{0}, std::uint64_t{7}, std::uint64_t{10}, std::uint64_t{255},
        std::uint64_t{4294967295u}, std::numeric_limits<std::uint64_t>::max()}) {
    char text[32];
    EXPECT_EQ(std::string(text, appendUnsigned(text, value)), std::to_string(value));
  }
}

}  // namespace
