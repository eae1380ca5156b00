// The tools' progress lines (common/progress_log.h): what a line says, and when one is printed.
#include <gtest/gtest.h>

#include <sstream>

#include "inekf_semantic_mapping/common/progress_log.h"

namespace inekf_semantic_mapping {
namespace common {
namespace {

TEST(ProgressLog, ALineSaysWhatIsDoneTheRateAndTheTimeLeft) {
  std::ostringstream out;
  const ProgressLog progress("evaluate_semantics: 05 labels", 120, "frames", 30.0, &out);
  EXPECT_EQ(progress.line(30, 15.0),
            "evaluate_semantics: 05 labels: 30 of 120 frames, 2 frames/s, about 45 s left");
  EXPECT_EQ(progress.line(0, 15.0), "evaluate_semantics: 05 labels: 0 of 120 frames");
  EXPECT_EQ(progress.line(120, 60.0),
            "evaluate_semantics: 05 labels: 120 of 120 frames, 2 frames/s");
  // Minutes past 90 s, hours past 90 min; fast loops without an exponent.
  EXPECT_EQ(progress.line(1, 31.0),
            "evaluate_semantics: 05 labels: 1 of 120 frames, 0.032 frames/s, about 61 min left");
  EXPECT_EQ(progress.line(1, 100.0),
            "evaluate_semantics: 05 labels: 1 of 120 frames, 0.01 frames/s, about 3.3 h left");
  EXPECT_EQ(progress.line(60, 0.6),
            "evaluate_semantics: 05 labels: 60 of 120 frames, 100 frames/s, about 1 s left");
}

TEST(ProgressLog, PrintsAtMostOncePerPeriod) {
  std::ostringstream every, never;
  ProgressLog each_update("maps", 3, "frames", 0.0, &every);
  ProgressLog long_period("maps", 3, "frames", 1e9, &never);
  for (std::size_t done = 1; done <= 3; ++done) {
    EXPECT_TRUE(each_update.update(done));
    EXPECT_FALSE(long_period.update(done));
  }
  EXPECT_EQ(never.str(), "");
  std::istringstream lines(every.str());
  std::string line;
  int count = 0;
  while (std::getline(lines, line)) {
    EXPECT_EQ(line.rfind("maps: " + std::to_string(++count) + " of 3 frames", 0), 0u) << line;
  }
  EXPECT_EQ(count, 3);
}

}  // namespace
}  // namespace common
}  // namespace inekf_semantic_mapping
