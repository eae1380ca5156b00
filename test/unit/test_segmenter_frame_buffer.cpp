// LatestFrameBuffer: the segmentation node's drop-stale-frames policy.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

#include "inekf_semantic_mapping/perception/latest_frame_buffer.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

TEST(LatestFrameBuffer, KeepsOnlyTheNewestFrameAndCountsDrops) {
  LatestFrameBuffer<int> buffer;
  EXPECT_FALSE(buffer.put(1));
  EXPECT_TRUE(buffer.put(2));  // 1 was never taken: dropped
  EXPECT_TRUE(buffer.put(3));
  EXPECT_EQ(buffer.take().value(), 3);
  EXPECT_EQ(buffer.droppedCount(), 2u);
  EXPECT_FALSE(buffer.put(4));  // the slot was emptied by take()
  EXPECT_EQ(buffer.take().value(), 4);
  EXPECT_EQ(buffer.putCount(), 4u);
}

TEST(LatestFrameBuffer, CloseWakesABlockedConsumer) {
  LatestFrameBuffer<int> buffer;
  std::optional<int> taken = 7;
  std::thread consumer([&] { taken = buffer.take(); });
  buffer.close();
  consumer.join();
  EXPECT_FALSE(taken.has_value());
}

TEST(LatestFrameBuffer, SlowConsumerSeesIncreasingFramesAndEveryFrameIsTakenOrDropped) {
  LatestFrameBuffer<int> buffer;
  std::vector<int> seen;  // read only after join()
  std::atomic<std::size_t> taken_count{0};
  std::thread consumer([&] {
    while (auto frame = buffer.take()) {
      seen.push_back(*frame);
      ++taken_count;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  });
  constexpr int kFrames = 2000;
  for (int i = 1; i <= kFrames; ++i) buffer.put(i);
  // Let the consumer drain the last frame, then stop it.
  while (buffer.droppedCount() + taken_count < static_cast<std::size_t>(kFrames))
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  buffer.close();
  consumer.join();
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back(), kFrames);  // the newest frame is never lost
  for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_LT(seen[i - 1], seen[i]);
  EXPECT_EQ(buffer.droppedCount() + seen.size(), static_cast<std::size_t>(kFrames));
  EXPECT_GT(buffer.droppedCount(), 0u);  // a slow consumer must have caused drops
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
