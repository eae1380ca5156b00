// ScanLabelPairing: which label image belongs to which lidar scan, and how long a scan waits for
// it; the streaming half of SemanticMappingSession, and the only place where scans and label
// images wait (the node hands over every label image as it comes, camera known or not).
//
// Rules (data time: the newest stamp seen, or the clock when nothing arrives):
// * A scan and a label image pair when their stamps are within label_stamp_tolerance_s, nearest
//   first, in whichever order they come.
// * A scan waits at most label_wait_s for its label image, and less once it is clear that none
//   will come: a newer label image is here (segmentation publishes in stamp order), or none has
//   arrived for a whole wait (segmentation is not running). Then it waits up to pose_wait_s more
//   for its pose, and is dropped after that.
// * A label image whose scan already went in without labels adds class evidence to it ("late"),
//   for scans kept kLateLabelWindow_s; one whose scan has not come waits until newer scans pass
//   it, at most kLabelKeepMax_s.
// * Stamps that go back by more than a second (a bag loop) restart the clock.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/mapping/camera_model.h"

namespace inekf_semantic_mapping {
namespace mapping {

struct MappingStatistics;

// A label image as it waits: a copy of its pixels, and its camera once known.
struct PendingLabels {
  double stamp = 0.0;
  std::vector<std::uint8_t> pixels;
  LabelImageView view;                // into pixels
  std::string camera_frame;           // for the camera lookup; may be empty
  std::optional<CameraModel> camera;  // unset while camera_info / tf have not come

  // Copies the view's rows (the caller's buffer may go away).
  static std::shared_ptr<PendingLabels> copyOf(double stamp, const LabelImageView& view);
};

struct PendingScan {
  double stamp = 0.0;
  std::string frame;
  Eigen::Matrix3Xf points_sensor;
  std::shared_ptr<PendingLabels> labels;  // its label image, once paired
  // Looked up while it waits for its label image: tf forgets it at a bag loop (the clock going
  // back clears tf's buffer), and the scans of a loop's end went without a pose.
  std::optional<Eigen::Isometry3d> pose;
};

// A scan that went in without labels, kept a while for a label image that comes late.
struct InsertedScan {
  double stamp = 0.0;
  Eigen::Matrix3Xf points_map;  // the points as inserted (cut to the camera's view)
  Eigen::Isometry3d T_map_sensor = Eigen::Isometry3d::Identity();
  std::string frame;                  // the scan's sensor frame (pose lookups)
  bool has_neighbour_labels = false;  // a neighbouring label image's evidence was added
};

struct PairingOptions {
  double label_stamp_tolerance_s = 0.05;
  double label_wait_s = 1.0;
  double pose_wait_s = 1.0;
};

class ScanLabelPairing {
 public:
  // `statistics` (kept by the caller) receives scans_without_pose and label_images_unmatched.
  ScanLabelPairing(const PairingOptions& options, MappingStatistics* statistics);

  // True if `stamp` is more than a second older than the newest scan (a bag loop): the caller
  // flushes what is pending and restarts the clock first.
  bool wentBack(double stamp) const;
  void addScan(PendingScan scan);

  enum class LabelsPlace {
    kPaired,     // with a pending scan
    kLate,       // applied to a scan that went in without labels (apply_late returned true)
    kWaiting,    // for its scan
    kUnmatched,  // no scan will come for it
  };
  // `apply_late` adds a label image's class evidence to an inserted scan, false if it cannot yet
  // (its camera is unknown); the scan leaves the late window when it returns true.
  using ApplyLate = std::function<bool(PendingLabels& labels, InsertedScan& scan)>;
  LabelsPlace addLabels(std::shared_ptr<PendingLabels> labels, const ApplyLate& apply_late);

  // Inserts a scan: true if it went in, false if it must wait (pose or camera not known yet).
  using Insert = std::function<bool(PendingScan& scan)>;
  // Data time has reached `now` (if later): the ready scans go to `insert`, in arrival order;
  // those whose pose never came are dropped; label images no scan will claim are let go.
  std::size_t insertReady(double now, const Insert& insert);
  // Every pending scan to `insert` (false: dropped); the waiting label images are let go.
  std::size_t flush(const Insert& insert);
  // Every pending scan to `insert` now, however long its label wait has left (false: it waits
  // on); the waiting label images stay. For a clock that has stopped: data time will not end
  // the wait.
  std::size_t insertWithoutWaiting(const Insert& insert);
  // A scan that went in without labels (its label image may still come).
  void keepForLateLabels(InsertedScan scan);
  // Those scans, oldest first, for the class evidence of a neighbouring label image.
  std::deque<InsertedScan>& scansWithoutLabels() { return unlabelled_scans_; }

  // Each pending scan that waits for its label image (to look up its pose while tf has it).
  void forEachWaitingForLabels(const std::function<void(PendingScan&)>& visit);

  // After a flush: the clocks start again and the late window empties (a new timeline).
  void restartClock();
  // Nothing pending, clocks from the start.
  void clear();

  double now() const { return newest_stamp_; }
  std::size_t pendingScans() const { return scans_.size(); }
  std::optional<double> oldestPendingStamp() const {
    return scans_.empty() ? std::nullopt : std::optional<double>(scans_.front().stamp);
  }
  std::size_t waitingLabelImages() const { return labels_.size(); }

 private:
  bool labelsMayStillCome(const PendingScan& scan, double now) const;

  PairingOptions options_;
  MappingStatistics* statistics_;
  std::deque<PendingScan> scans_;
  std::deque<std::shared_ptr<PendingLabels>> labels_;
  std::deque<InsertedScan> unlabelled_scans_;
  double newest_stamp_ = -1e300;  // newest scan or label stamp, or clock (data time)
  // Newest scan stamp: scans arrive in stamp order, so once it has passed a label image's stamp
  // no scan of that stamp will come, however far the clock is ahead (a lagging scan queue).
  double newest_scan_stamp_ = -1e300;
  double newest_label_stamp_ = -1e300;  // newest label image
  double first_stamp_ = 1e300;          // first scan or label image of this timeline
  double last_label_arrival_ = -1e300;  // data time when the newest label image arrived
  // The newest stamp of the timeline before the last restart: label images stamped up to it and
  // ahead of this one are that timeline's (segmentation finishing a frame of before a bag loop).
  double previous_timeline_end_ = -1e300;
  // Whether the timeline before the last restart had label images: if not (a lidar-only run),
  // the scans of this one do not wait for a first label image.
  bool labels_in_previous_timeline_ = true;
};

}  // namespace mapping
}  // namespace inekf_semantic_mapping
