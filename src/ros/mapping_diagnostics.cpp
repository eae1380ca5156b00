#include "inekf_semantic_mapping/ros/mapping_diagnostics.h"

#include <algorithm>
#include <cstdio>
#include <optional>
#include <utility>

namespace inekf_semantic_mapping {
namespace ros_conversions {

namespace {
using diagnostic_msgs::DiagnosticStatus;
constexpr std::size_t kMaxWaitingStamps = 500;
// One scan in this many dropped without a pose over the window: WARN (half: ERROR).
constexpr std::size_t kDropsWarnShare = 10;
// Wall seconds without any pose (no scan in the map yet) before the status is an ERROR.
constexpr double kFirstPoseErrorS = 30.0;

std::string saveText(const SaveRecord& record, double wall_s) {
  if (record.wall_s < 0) return "never";
  char ago[32];
  std::snprintf(ago, sizeof ago, "%.0f s ago", wall_s - record.wall_s);
  return record.path + ", " + ago + (record.ok ? "" : ", FAILED: " + record.error);
}
}  // namespace

void readMappingDiagnosticsOptions(common::YamlReader* reader, MappingDiagnosticsOptions* options) {
  for (const auto& [key, value] : {std::pair{"window_s", &options->window_s},
                                   {"label_stall_warn_s", &options->label_stall_warn_s},
                                   {"max_latency_warn_s", &options->max_latency_warn_s}}) {
    reader->read(key, value);
    if (!(*value > 0)) reader->fail(key, "must be > 0");
  }
}

MappingMonitor::MappingMonitor(MappingDiagnosticsOptions options)
    : options_(options),
      scans_in_(options.window_s),
      scans_inserted_(options.window_s),
      scans_refused_(options.window_s) {}

void MappingMonitor::noteScanRefused(double wall_s, const std::string& why) {
  scans_refused_.add(wall_s);
  ++scans_refused_total_;
  last_refusal_ = why;
}

void MappingMonitor::noteScan(double stamp_s, double wall_s) {
  scans_in_.add(wall_s);
  if (first_scan_wall_s_ < 0) first_scan_wall_s_ = wall_s;
  last_scan_wall_s_ = wall_s;
  arrival_wall_s_[stamp_s] = wall_s;
  while (arrival_wall_s_.size() > kMaxWaitingStamps) arrival_wall_s_.erase(arrival_wall_s_.begin());
}

void MappingMonitor::noteInserted(double stamp_s, double wall_s) {
  const auto found = arrival_wall_s_.find(stamp_s);
  const double latency_s = found == arrival_wall_s_.end() ? 0.0 : wall_s - found->second;
  if (found != arrival_wall_s_.end()) arrival_wall_s_.erase(found);
  scans_inserted_.add(wall_s, latency_s);
}

void MappingMonitor::noteLabelImage(double wall_s) { last_label_wall_s_ = wall_s; }

double MappingMonitor::oldestWaitS(const mapping::SemanticMappingSession& session,
                                   double wall_s) const {
  const std::optional<double> stamp = session.oldestPendingStamp();
  if (!stamp) return 0.0;
  const auto arrival = arrival_wall_s_.find(*stamp);
  return arrival == arrival_wall_s_.end() ? 0.0 : wall_s - arrival->second;
}

std::pair<std::size_t, std::size_t> MappingMonitor::recentDrops(
    const mapping::MappingStatistics& stats, double wall_s) {
  // A reset (statistics from zero) starts the count again: seen by either count going down
  // (more scans may have come since the reset than before it).
  if (!drop_counts_.empty() && (stats.scans_received < drop_counts_.back().received ||
                                stats.scans_without_pose < drop_counts_.back().without_pose)) {
    drop_counts_.clear();
  }
  // Until a scan first goes in, drops are the wait for the first pose (fillMap says so); the
  // window counts from the first status after it (the scans inserted by then came after them).
  if (stats.scans_inserted == 0) {
    drop_counts_.clear();
    return {0, 0};
  }
  if (drop_counts_.empty()) {
    drop_counts_.push_back(
        {wall_s, stats.scans_received - stats.scans_inserted, stats.scans_without_pose});
  }
  drop_counts_.push_back({wall_s, stats.scans_received, stats.scans_without_pose});
  while (drop_counts_.size() > 1 && drop_counts_[1].wall_s <= wall_s - options_.window_s) {
    drop_counts_.pop_front();
  }
  const DropCount& oldest = drop_counts_.front();
  // The first status counts from the start.
  if (drop_counts_.size() == 1) return {stats.scans_received, stats.scans_without_pose};
  // A reset between two statuses that took both counts above their old values is not seen:
  // never more drops than scans.
  const std::size_t received = stats.scans_received - oldest.received;
  return {received, std::min(received, stats.scans_without_pose - oldest.without_pose)};
}

void MappingMonitor::fillMap(const mapping::SemanticMappingSession& session, const SaveRecord& save,
                             const SaveRecord& autosave, double wall_s,
                             diagnostic_updater::DiagnosticStatusWrapper* status) {
  scans_in_.expire(wall_s);
  scans_inserted_.expire(wall_s);
  scans_refused_.expire(wall_s);
  const mapping::MappingStatistics& stats = session.statistics();
  const double p95_s = scans_inserted_.percentile(0.95);
  unsigned char level = DiagnosticStatus::OK;
  std::string message = stats.scans_received == 0 ? "waiting for scans" : "mapping";
  if (p95_s > options_.max_latency_warn_s) {
    level = DiagnosticStatus::WARN;
    message = "falling behind: insertion latency p95 above " +
              std::to_string(options_.max_latency_warn_s) + " s";
  }
  const double waited_s = oldestWaitS(session, wall_s);
  if (waited_s > options_.max_latency_warn_s) {
    level = DiagnosticStatus::WARN;
    char text[160];
    std::snprintf(text, sizeof text,
                  "%zu scans waiting for %.0f s (for their pose in tf, or their label images "
                  "while the clock runs)",
                  session.pendingScans(), waited_s);
    message = text;
  }
  if ((save.wall_s >= 0 && !save.ok) || (autosave.wall_s >= 0 && !autosave.ok)) {
    level = DiagnosticStatus::WARN;
    message = "the last save failed";
  }
  // Over the window, not since the start: a share of drops is said while it lasts (a quarter of
  // a looping bag's scans went without a pose under "mapping" OK) and clears when it ends.
  // No pose yet at all: the localization has not started or waits for its heading (inekf_node's
  // tf does), or tf does not link the map to the sensor: WARN, ERROR after kFirstPoseErrorS (a
  // normal start without an IMU orientation read ERROR "most scans dropped" for seconds).
  if (stats.scans_inserted == 0 && stats.scans_without_pose > 0) {
    if (waiting_for_pose_since_wall_s_ < 0) waiting_for_pose_since_wall_s_ = wall_s;
    const double waited_s = wall_s - waiting_for_pose_since_wall_s_;
    const unsigned char waiting_level =
        waited_s > kFirstPoseErrorS ? DiagnosticStatus::ERROR : DiagnosticStatus::WARN;
    level = std::max(level, waiting_level);
    char text[160];
    std::snprintf(text, sizeof text,
                  "no scan has had a pose yet (%zu dropped over %.0f s: map -> sensor not in tf)",
                  stats.scans_without_pose, waited_s);
    message = text;
  } else if (stats.scans_inserted > 0) {
    waiting_for_pose_since_wall_s_ = -1.0;
  }
  const auto [received, without_pose] = recentDrops(stats, wall_s);
  if (received >= 5 && without_pose * kDropsWarnShare > received) {
    const bool most = without_pose * 2 > received;
    const unsigned char drops_level = most ? DiagnosticStatus::ERROR : DiagnosticStatus::WARN;
    level = std::max(level, drops_level);
    message = std::string(most ? "most" : "some") + " scans dropped without a pose (" +
              std::to_string(without_pose) + " of the last " + std::to_string(received) +
              "; map -> sensor not in tf in time)";
  }
  // Clouds the node could not read: nothing of them reaches the map (an Ouster's integer x/y/z
  // left "waiting for scans" OK while every scan was refused).
  const std::size_t refused = scans_refused_.count();
  if (refused > 0) {
    const bool most = 2 * refused > scans_in_.count();
    const unsigned char refused_level = most ? DiagnosticStatus::ERROR : DiagnosticStatus::WARN;
    level = std::max(level, refused_level);
    message = std::string(most ? "most" : "some") + " scans refused (" + std::to_string(refused) +
              " of the last " + std::to_string(std::max(refused, scans_in_.count())) +
              "): " + last_refusal_;
  }
  status->summary(level, message);
  status->addf("scan rate in (Hz)", "%.2f", scans_in_.rateOverWindowHz(wall_s));
  status->addf("scan rate into the map (Hz)", "%.2f", scans_inserted_.rateOverWindowHz(wall_s));
  status->add("scans received", stats.scans_received);
  status->add("scans inserted", stats.scans_inserted);
  status->add("pending scans", session.pendingScans());
  status->addf("oldest pending scan waiting (s)", "%.1f", waited_s);
  status->add("scans without pose", stats.scans_without_pose);
  status->add("scans rejected by the map", stats.scans_rejected);
  status->add("scans refused (unreadable)", scans_refused_total_);
  status->add("last refusal", last_refusal_.empty() ? "none" : last_refusal_);
  status->addf("insertion latency p50 (s)", "%.3f", scans_inserted_.percentile(0.5));
  status->addf("insertion latency p95 (s)", "%.3f", p95_s);
  status->add("map size", session.mapSizeText());
  status->addf("map memory (MB)", "%.1f", session.mapMemoryUsage() / 1e6);
  status->add("last save", saveText(save, wall_s));
  status->add("last autosave", saveText(autosave, wall_s));
}

void MappingMonitor::fillLabels(const mapping::SemanticMappingSession& session,
                                bool labels_expected, double wall_s,
                                diagnostic_updater::DiagnosticStatusWrapper* status) {
  const mapping::MappingStatistics& stats = session.statistics();
  const double since_label_s = last_label_wall_s_ >= 0   ? wall_s - last_label_wall_s_
                               : first_scan_wall_s_ >= 0 ? wall_s - first_scan_wall_s_
                                                         : 0.0;
  const bool scans_coming =
      last_scan_wall_s_ >= 0 && wall_s - last_scan_wall_s_ < options_.label_stall_warn_s;
  if (!labels_expected) {
    status->summary(DiagnosticStatus::OK, "no label publisher (occupancy only)");
  } else if (stats.label_images_refused >= kLabelsBeforeUnmatchedWarning &&
             stats.label_images_refused > stats.label_images_received) {
    status->summary(DiagnosticStatus::WARN,
                    "most label images refused (not mono8 label ids, malformed, or not of their "
                    "camera's size): see the node's log");
  } else if (mostLabelImagesUnmatched(stats)) {
    status->summary(DiagnosticStatus::WARN,
                    "most label images match no scan (stamps more than label_stamp_tolerance_s "
                    "from every scan's)");
  } else if (scans_coming && since_label_s > options_.label_stall_warn_s) {
    status->summary(DiagnosticStatus::WARN, "segmentation stalled: no label image for " +
                                                std::to_string(static_cast<int>(since_label_s)) +
                                                " s while scans arrive");
  } else {
    status->summary(DiagnosticStatus::OK, "labels arriving");
  }
  status->add("labels expected", labels_expected ? "yes" : "no");
  status->add("label images received", stats.label_images_received);
  status->add("label images refused", stats.label_images_refused);
  status->add("label images used", stats.label_images_used);
  status->add("label images late", stats.label_images_late);
  status->add("scans with a neighbour's labels", stats.scans_with_neighbour_labels);
  status->add("label images unmatched", stats.label_images_unmatched);
  status->add("label images without camera", stats.label_images_without_camera);
  status->add("scans with labels", stats.scans_with_labels);
  status->addf("since last label image (s)", "%.1f", since_label_s);
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
