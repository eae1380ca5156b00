// A one-slot mailbox between a producer (camera callback) and a slower consumer (inference
// thread): a new frame replaces one that was not yet taken, so the consumer always works on the
// newest frame and stale frames are dropped (and counted) instead of queueing up latency.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>

namespace inekf_semantic_mapping {
namespace perception {

template <typename Frame>
class LatestFrameBuffer {
 public:
  // Stores the frame; returns true when it replaced an untaken (now dropped) frame.
  bool put(Frame frame) {
    bool dropped = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      dropped = slot_.has_value();
      if (dropped) ++dropped_count_;
      slot_ = std::move(frame);
      ++put_count_;
    }
    ready_.notify_one();
    return dropped;
  }

  // Blocks until a frame is there or close() was called; empty after close().
  std::optional<Frame> take() {
    std::unique_lock<std::mutex> lock(mutex_);
    ready_.wait(lock, [this] { return slot_.has_value() || closed_; });
    if (!slot_) return std::nullopt;
    std::optional<Frame> frame = std::move(slot_);
    slot_.reset();
    return frame;
  }

  // Wakes a blocked take() for shutdown; later put() calls still store but take() returns them
  // only until the slot is empty.
  void close() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
  }

  std::uint64_t droppedCount() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_count_;
  }
  std::uint64_t putCount() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return put_count_;
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::optional<Frame> slot_;
  bool closed_ = false;
  std::uint64_t dropped_count_ = 0;
  std::uint64_t put_count_ = 0;
};

}  // namespace perception
}  // namespace inekf_semantic_mapping
