#include "inekf_semantic_mapping/mapping/scan_label_pairing.h"

#include <algorithm>
#include <cmath>

#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

// Label images are kept this long past the newest scan for a scan that may still come (s).
constexpr double kLabelKeepMargin_s = 1.0;
// ... and at most this long past the clock (data time, s) when no newer scan comes at all (lidar
// stopped): it bounds the memory of the label images waiting, not the lag of the scan queue.
constexpr double kLabelKeepMax_s = 30.0;
// Scans that went in without labels are kept this long (data time) for a late label image.
constexpr double kLateLabelWindow_s = 10.0;
// A stamp this much older than the newest one means the clock went back (a bag loop).
constexpr double kTimeJump_s = 1.0;
// For this long (data time) after a bag loop a label image stamped in the ended timeline is
// taken for one of its leftovers.
constexpr double kPreviousTimelineLeftovers_s = 5.0;

double stampOf(const PendingScan& scan) { return scan.stamp; }
double stampOf(const InsertedScan& scan) { return scan.stamp; }
double stampOf(const std::shared_ptr<PendingLabels>& labels) { return labels->stamp; }

// The item of `items` (scans or label images) whose stamp is nearest to `stamp`, within
// `tolerance`, among those `eligible` accepts; items.end() if none.
template <typename Items, typename Eligible>
auto nearestInTime(Items& items, double stamp, double tolerance, Eligible eligible) {
  auto best = items.end();
  for (auto it = items.begin(); it != items.end(); ++it) {
    const double gap = std::abs(stampOf(*it) - stamp);
    if (eligible(*it) && gap <= tolerance &&
        (best == items.end() || gap < std::abs(stampOf(*best) - stamp))) {
      best = it;
    }
  }
  return best;
}
constexpr auto kAny = [](const auto&) { return true; };

}  // namespace

std::shared_ptr<PendingLabels> PendingLabels::copyOf(double stamp, const LabelImageView& view) {
  auto copy = std::make_shared<PendingLabels>();
  copy->stamp = stamp;
  const std::size_t row = static_cast<std::size_t>(view.width);
  copy->pixels.resize(row * static_cast<std::size_t>(view.height));
  for (int r = 0; r < view.height; ++r) {
    std::copy_n(view.data + static_cast<std::size_t>(r) * view.step, row,
                copy->pixels.data() + static_cast<std::size_t>(r) * row);
  }
  copy->view = LabelImageView{copy->pixels.data(), view.width, view.height, row};
  return copy;
}

ScanLabelPairing::ScanLabelPairing(const PairingOptions& options, MappingStatistics* statistics)
    : options_(options), statistics_(statistics) {}

bool ScanLabelPairing::wentBack(double stamp) const {
  // Against the newest scan, not the clock: a scan that sat in a busy subscriber queue is older
  // than the clock by the queue's lag, and that is no bag loop.
  return stamp + kTimeJump_s < newest_scan_stamp_;
}

void ScanLabelPairing::addScan(PendingScan scan) {
  // A label image that came first (segmentation can beat the pose or the cloud's transport).
  const auto best = nearestInTime(labels_, scan.stamp, options_.label_stamp_tolerance_s, kAny);
  if (best != labels_.end()) {
    scan.labels = std::move(*best);
    labels_.erase(best);
  }
  newest_stamp_ = std::max(newest_stamp_, scan.stamp);
  newest_scan_stamp_ = std::max(newest_scan_stamp_, scan.stamp);
  first_stamp_ = std::min(first_stamp_, scan.stamp);
  scans_.push_back(std::move(scan));
}

ScanLabelPairing::LabelsPlace ScanLabelPairing::addLabels(std::shared_ptr<PendingLabels> labels,
                                                          const ApplyLate& apply_late) {
  const double stamp = labels->stamp;
  const double tolerance = options_.label_stamp_tolerance_s;
  // Only in the first seconds of the new timeline: the old one's leftovers come within a
  // segmentation latency of the jump.
  const bool just_restarted = newest_stamp_ - first_stamp_ <= kPreviousTimelineLeftovers_s;
  if (just_restarted && stamp > newest_stamp_ + kTimeJump_s &&
      stamp <= previous_timeline_end_ + kTimeJump_s) {
    // Of the timeline that ended (a bag loop): as one of the present it moved the clock seconds
    // ahead, and the new timeline's scans, suddenly "old", were dropped waiting for their poses.
    ++statistics_->label_images_unmatched;
    return LabelsPlace::kUnmatched;
  }
  // Its scan, in this order: still pending (waiting for labels or its pose), already in the map
  // without labels (the labels add class evidence), or not here yet. The scans' own stamps decide
  // the last case, not the clock: under load the scan queue can lag the clock by more than
  // label_wait, and the scan still comes.
  const auto pending =
      nearestInTime(scans_, stamp, tolerance, [](const PendingScan& scan) { return !scan.labels; });
  const bool scan_may_come = stamp + tolerance >= newest_scan_stamp_;
  if (pending != scans_.end() || scan_may_come) {
    // A label image of the present: it moves the clocks (one for a scan long gone does not).
    newest_label_stamp_ = std::max(newest_label_stamp_, stamp);
    newest_stamp_ = std::max(newest_stamp_, stamp);
    first_stamp_ = std::min(first_stamp_, stamp);
    last_label_arrival_ = newest_stamp_;
  }
  if (pending != scans_.end()) {
    pending->labels = std::move(labels);
    return LabelsPlace::kPaired;
  }
  const auto late = nearestInTime(unlabelled_scans_, stamp, tolerance, kAny);
  if (late != unlabelled_scans_.end() && apply_late(*labels, *late)) {
    unlabelled_scans_.erase(late);
    return LabelsPlace::kLate;
  }
  if (scan_may_come) {
    labels_.push_back(std::move(labels));
    return LabelsPlace::kWaiting;
  }
  ++statistics_->label_images_unmatched;
  return LabelsPlace::kUnmatched;
}

bool ScanLabelPairing::labelsMayStillCome(const PendingScan& scan, double now) const {
  if (scan.labels) return false;
  // Segmentation publishes in stamp order: once a newer label image is here, none will come
  // for this scan.
  if (newest_label_stamp_ > scan.stamp + options_.label_stamp_tolerance_s) return false;
  // No label image has arrived for a whole wait (data time of its arrival, not its stamp: a
  // label image comes one segmentation latency after its stamp), and the run is older than that:
  // segmentation is not running (lidar-only runs). At the start, scans wait for the first one.
  // After a restart, a run whose last timeline had no label image does not wait at all.
  if (last_label_arrival_ < now - options_.label_wait_s &&
      (first_stamp_ < now - options_.label_wait_s || !labels_in_previous_timeline_)) {
    return false;
  }
  return now - scan.stamp <= options_.label_wait_s;
}

std::size_t ScanLabelPairing::insertReady(double now, const Insert& insert) {
  if (std::isfinite(now)) newest_stamp_ = std::max(newest_stamp_, now);
  now = newest_stamp_;
  std::size_t inserted = 0;
  for (auto it = scans_.begin(); it != scans_.end();) {
    if (labelsMayStillCome(*it, now)) {
      ++it;
      continue;
    }
    if (insert(*it)) {
      ++inserted;
      it = scans_.erase(it);
    } else if (now - it->stamp > options_.label_wait_s + options_.pose_wait_s) {
      ++statistics_->scans_without_pose;
      it = scans_.erase(it);
    } else {
      ++it;
    }
  }
  // Label images no scan will claim any more: newer scans have come (scans arrive in stamp
  // order), or none has for a long time.
  for (auto it = labels_.begin(); it != labels_.end();) {
    const double stamp = (*it)->stamp;
    if (stamp + kLabelKeepMargin_s < newest_scan_stamp_ || stamp + kLabelKeepMax_s < now) {
      ++statistics_->label_images_unmatched;
      it = labels_.erase(it);
    } else {
      ++it;
    }
  }
  return inserted;
}

std::size_t ScanLabelPairing::flush(const Insert& insert) {
  const std::size_t inserted = insertWithoutWaiting(insert);
  statistics_->scans_without_pose += scans_.size();  // those `insert` could not take
  scans_.clear();
  statistics_->label_images_unmatched += labels_.size();
  labels_.clear();
  return inserted;
}

std::size_t ScanLabelPairing::insertWithoutWaiting(const Insert& insert) {
  std::size_t inserted = 0;
  for (auto it = scans_.begin(); it != scans_.end();) {
    if (insert(*it)) {
      ++inserted;
      it = scans_.erase(it);
    } else {
      ++it;
    }
  }
  return inserted;
}

void ScanLabelPairing::keepForLateLabels(InsertedScan scan) {
  const double oldest_kept = scan.stamp - kLateLabelWindow_s;
  unlabelled_scans_.push_back(std::move(scan));
  while (!unlabelled_scans_.empty() && unlabelled_scans_.front().stamp < oldest_kept) {
    unlabelled_scans_.pop_front();
  }
}

void ScanLabelPairing::forEachWaitingForLabels(const std::function<void(PendingScan&)>& visit) {
  for (PendingScan& scan : scans_) {
    if (labelsMayStillCome(scan, newest_stamp_)) visit(scan);
  }
}

void ScanLabelPairing::restartClock() {
  unlabelled_scans_.clear();
  previous_timeline_end_ = newest_stamp_;
  labels_in_previous_timeline_ = newest_label_stamp_ > -1e299;
  newest_stamp_ = newest_scan_stamp_ = newest_label_stamp_ = last_label_arrival_ = -1e300;
  first_stamp_ = 1e300;
}

void ScanLabelPairing::clear() {
  scans_.clear();
  labels_.clear();
  restartClock();
  // A new map (~reset): as at the start, not as after a bag loop.
  previous_timeline_end_ = -1e300;
  labels_in_previous_timeline_ = true;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
