// The segmentation node's work, shared by segmentation_node and the segmentation nodelet
// (see ros/segmentation_node_core.h).
#include "inekf_semantic_mapping/ros/segmentation_node_core.h"

#include <cv_bridge/cv_bridge.h>
#include <image_transport/image_transport.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <opencv2/imgproc.hpp>
#include <string>
#include <thread>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/perception/latest_frame_buffer.h"
#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"
#include "inekf_semantic_mapping/ros/diagnostics.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "inekf_semantic_mapping/ros/node_parameters.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

namespace enc = sensor_msgs::image_encodings;

struct Frame {
  std_msgs::Header header;
  cv::Mat image;  // BGR or gray, owned
};

}  // namespace

class SegmentationNodeCore::Impl {
 public:
  Impl(ros::NodeHandle& nh, ros::NodeHandle& pnh) : transport_(nh), diagnostics_(nh, pnh) {
    common::YamlReader parameters = privateParameterReader(pnh);
    std::string model, card_path, image_topic = topics::kCameraColorLeftImage;
    int num_threads = 2;
    parameters.read("model", &model);
    parameters.read("model_card", &card_path);
    parameters.read("image_topic", &image_topic);
    parameters.read("publish_overlay", &publish_overlay_);
    // Ranges checked as the other nodes' are (an alpha of 2 went to cv::addWeighted as 2 and -1).
    parameters.readInRange("overlay_alpha", &overlay_alpha_, 0.0, 1.0);
    parameters.readInRange("num_threads", &num_threads, 1, 256);
    parameters.readInRange("rate_log_period_s", &rate_log_period_s_, 0.0, 3600.0, true);
    parameters.read("diagnostics.latency_warn_s", &latency_warn_s_);
    parameters.allow("image_transport");  // image_transport's own choice of transport
    parameters.rejectUnknown();
    if (model.empty()) parameters.fail("model", "is not set (the segmentation network)");

    const perception::ModelCard card = card_path.empty() ? perception::defaultModelCardFor(model)
                                                         : perception::loadModelCard(card_path);
    segmenter_ = std::make_unique<perception::Segmenter>(model, card, num_threads);
    ROS_INFO_STREAM("segmentation_node: model "
                    << model << ", card " << card.source << " (" << card.numOutputChannels()
                    << " classes, " << perception::resizePolicyName(card.resize_policy) << ")");

    diagnostics_.add("segmentation", [this, model](auto& status) { fillStatus(model, &status); });
    labels_publisher_ = transport_.advertise(topics::kSegmentationLabels, 1);
    overlay_publisher_ = transport_.advertise(topics::kSegmentationOverlay, 1);
    // The transport (~image_transport) from this node's own namespace: image_transport's default
    // hints read the process's, which in a nodelet manager is the manager's.
    image_subscriber_ =
        transport_.subscribe(image_topic, 1, &Impl::imageCallback, this,
                             image_transport::TransportHints("raw", ros::TransportHints(), pnh));
    // Started last: a subscription that throws (a bad topic name, a transport not installed)
    // must not leave a running thread behind (its destructor would terminate the process, a
    // nodelet manager with it).
    worker_ = std::thread([this] { inferenceLoop(); });
    ROS_INFO_STREAM("segmentation_node: listening on " << image_subscriber_.getTopic());
  }

  ~Impl() {
    image_subscriber_.shutdown();
    frames_.close();
    if (worker_.joinable()) worker_.join();
  }

 private:
  void imageCallback(const sensor_msgs::ImageConstPtr& msg) {
    Frame frame;
    frame.header = msg->header;
    if (msg->width == 0 || msg->height == 0) {
      ROS_ERROR_STREAM_THROTTLE(5.0, "segmentation_node: image on "
                                         << image_subscriber_.getTopic() << " at "
                                         << msg->header.stamp << " is " << msg->width << "x"
                                         << msg->height << " (frame skipped)");
      noteRejectedFrame();
      return;
    }
    try {
      // Whatever cv_bridge turns into 8-bit BGR or grey (a camera driver's image_raw is often
      // Bayer, bgra8 or 16-bit): mono stays mono, the rest becomes bgr8.
      const bool mono = msg->encoding == enc::MONO8 || msg->encoding == enc::MONO16;
      frame.image = cv_bridge::toCvCopy(msg, mono ? enc::MONO8 : enc::BGR8)->image;
    } catch (const std::exception& e) {  // cv_bridge's own, and OpenCV's from its conversion
      ROS_ERROR_STREAM_THROTTLE(5.0, "segmentation_node: cannot convert image on "
                                         << image_subscriber_.getTopic() << " (" << msg->width
                                         << "x" << msg->height << " " << msg->encoding
                                         << ") to bgr8 or mono8: " << e.what()
                                         << " (frame skipped)");
      noteRejectedFrame();
      return;
    }
    frames_.put(std::move(frame));
  }

  void inferenceLoop() {
    auto last_log = std::chrono::steady_clock::now();
    std::uint64_t processed_since_log = 0;
    std::uint64_t dropped_at_log = 0;
    double inference_s_since_log = 0.0;
    while (std::optional<Frame> frame = frames_.take()) {
      const auto start = std::chrono::steady_clock::now();
      bool ok = false;
      try {
        segmentAndPublish(*frame);
        ok = true;
      } catch (const std::exception& e) {
        ROS_ERROR_STREAM_THROTTLE(5.0, "segmentation_node: frame at "
                                           << frame->header.stamp << " (" << frame->image.cols
                                           << "x" << frame->image.rows << "): " << e.what());
      }
      const auto now = std::chrono::steady_clock::now();
      const double frame_s = std::chrono::duration<double>(now - start).count();
      {
        std::lock_guard<std::mutex> lock(window_mutex_);
        (ok ? frames_done_ : frames_failed_).add(wallNow(), frame_s);
      }
      inference_s_since_log += frame_s;
      ++processed_since_log;
      const double since_log_s = std::chrono::duration<double>(now - last_log).count();
      if (since_log_s >= rate_log_period_s_) {
        const std::uint64_t dropped = frames_.droppedCount();
        ROS_INFO_STREAM("segmentation_node: " << processed_since_log / since_log_s << " Hz, "
                                              << 1e3 * inference_s_since_log / processed_since_log
                                              << " ms per frame, dropped "
                                              << dropped - dropped_at_log << " stale frames ("
                                              << dropped << " of " << frames_.putCount()
                                              << " in total)");
        last_log = now;
        processed_since_log = 0;
        dropped_at_log = dropped;
        inference_s_since_log = 0.0;
      }
    }
  }

  // Level: every frame of the window failed: ERROR; latency p95 above diagnostics/latency_warn_s
  // or some frames failed: WARN. Dropping stale frames is the design (the newest frame wins).
  void fillStatus(const std::string& model, diagnostic_updater::DiagnosticStatusWrapper* status) {
    std::lock_guard<std::mutex> lock(window_mutex_);
    const double now = wallNow();
    frames_done_.expire(now);
    frames_failed_.expire(now);
    const double p95_s = frames_done_.percentile(0.95);
    using diagnostic_msgs::DiagnosticStatus;
    if (frames_failed_.count() > 0 && frames_done_.count() == 0) {
      status->summary(DiagnosticStatus::ERROR, "every frame failed");
    } else if (frames_failed_.count() > 0) {
      status->summary(DiagnosticStatus::WARN, "some frames failed");
    } else if (p95_s > latency_warn_s_) {
      status->summary(DiagnosticStatus::WARN, "slow: latency p95 above the limit");
    } else {
      status->summary(DiagnosticStatus::OK,
                      frames_.putCount() == 0 ? "waiting for images" : "segmenting");
    }
    const perception::ModelCard& card = segmenter_->card();
    status->add("model", model);
    status->add("input size", std::to_string(card.input_width) + "x" +
                                  std::to_string(card.input_height) + " (" +
                                  perception::resizePolicyName(card.resize_policy) + ")");
    status->add("image topic", image_subscriber_.getTopic());
    status->addf("frame rate (Hz)", "%.2f", frames_done_.rateOverWindowHz(now));
    status->addf("latency mean (ms)", "%.1f", 1e3 * frames_done_.mean());
    status->addf("latency p95 (ms)", "%.1f", 1e3 * p95_s);
    status->add("frames received", frames_.putCount());
    status->add("dropped stale frames", frames_.droppedCount());
    status->add("failed frames in window", frames_failed_.count());
  }

  // A frame refused as it came counts as failed: the status said OK "segmenting" while every
  // frame of a camera in an unreadable encoding was dropped.
  void noteRejectedFrame() {
    std::lock_guard<std::mutex> lock(window_mutex_);
    frames_failed_.add(wallNow(), 0.0);
  }

  void segmentAndPublish(const Frame& frame) {
    perception::Segmentation result;
    {
      ScopedTimer timer("segmentation_node/segment");
      result = segmenter_->segment(frame.image);
    }
    // The card's label filter: doubtful pixels (low confidence, label edges) go out as
    // "unlabeled", which the map takes as no class evidence.
    const cv::Mat labels = perception::filterLabels(result, segmenter_->card().label_filter);
    labels_publisher_.publish(cv_bridge::CvImage(frame.header, enc::MONO8, labels).toImageMsg());
    if (publish_overlay_ && overlay_publisher_.getNumSubscribers() > 0) {
      const cv::Mat overlay = perception::overlayLabelIds(frame.image, labels, overlay_alpha_);
      overlay_publisher_.publish(cv_bridge::CvImage(frame.header, enc::RGB8, overlay).toImageMsg());
    }
  }

  image_transport::ImageTransport transport_;
  image_transport::Subscriber image_subscriber_;
  image_transport::Publisher labels_publisher_;
  image_transport::Publisher overlay_publisher_;
  std::unique_ptr<perception::Segmenter> segmenter_;
  perception::LatestFrameBuffer<Frame> frames_;
  std::thread worker_;
  bool publish_overlay_ = true;
  double overlay_alpha_ = 0.5;
  double rate_log_period_s_ = 10.0;
  double latency_warn_s_ = 2.0;
  std::mutex window_mutex_;  // the windows: written by the worker, read by the diagnostics
  EventWindow frames_done_, frames_failed_;  // wall time, latency (s)
  NodeDiagnostics diagnostics_;
};

SegmentationNodeCore::SegmentationNodeCore(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : impl_(std::make_unique<Impl>(nh, private_nh)) {}

SegmentationNodeCore::~SegmentationNodeCore() = default;

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
