// semantic_octomap_node's /diagnostics: a "map" status (scans in and into the map, pending,
// without pose, insertion latency, the map's size and memory, the last save and autosave) and a
// "labels" status (label images received, used, late; a segmentation that stalled while scans
// keep coming turns it WARN). Rates and latencies on the wall clock: they say whether the node
// keeps up with what arrives. ROS-facing (src/ros): only nodes and their tests include this.
#pragma once

#include <diagnostic_updater/DiagnosticStatusWrapper.h>

#include <deque>
#include <map>
#include <string>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/ros/diagnostics.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

// Label images received before "most of them matched no scan" is said (the status and the
// node's log line): a few at the ends of a run match none.
constexpr std::size_t kLabelsBeforeUnmatchedWarning = 5;

// True when most of the label images received matched no scan.
inline bool mostLabelImagesUnmatched(const mapping::MappingStatistics& s) {
  return s.label_images_received >= kLabelsBeforeUnmatchedWarning &&
         2 * s.label_images_unmatched > s.label_images_received;
}

struct MappingDiagnosticsOptions {
  double window_s = 10.0;            // rates and latency percentiles over this many wall seconds
  double label_stall_warn_s = 10.0;  // no label image for this long while scans come: WARN
  double max_latency_warn_s = 5.0;   // insertion latency p95 above it: WARN (falling behind)
};

// window_s, label_stall_warn_s, max_latency_warn_s of a reader of ~diagnostics/.
void readMappingDiagnosticsOptions(common::YamlReader* reader, MappingDiagnosticsOptions* options);

struct SaveRecord {
  std::string path;
  double wall_s = -1.0;  // < 0: never
  bool ok = false;
  std::string error;
};

class MappingMonitor {
 public:
  explicit MappingMonitor(MappingDiagnosticsOptions options);
  void noteScan(double stamp_s, double wall_s);
  // A cloud the node could not read (a field's type, no frame_id, ...): counted, said in the
  // status while it lasts (WARN; ERROR when most scans of the window are refused).
  void noteScanRefused(double wall_s, const std::string& why);
  void noteInserted(double stamp_s, double wall_s);  // latency: since its scan arrived
  void noteLabelImage(double wall_s);
  // labels_expected: a label publisher is connected or label images came before.
  void fillMap(const mapping::SemanticMappingSession& session, const SaveRecord& save,
               const SaveRecord& autosave, double wall_s,
               diagnostic_updater::DiagnosticStatusWrapper* status);
  void fillLabels(const mapping::SemanticMappingSession& session, bool labels_expected,
                  double wall_s, diagnostic_updater::DiagnosticStatusWrapper* status);

 private:
  // Wall seconds since the oldest scan still pending arrived (0: none pending).
  double oldestWaitS(const mapping::SemanticMappingSession& session, double wall_s) const;

  // Scans received and dropped without a pose over the window: (wall s, received, dropped) at
  // each status, the oldest within window_s.
  struct DropCount {
    double wall_s;
    std::size_t received, without_pose;
  };
  std::pair<std::size_t, std::size_t> recentDrops(const mapping::MappingStatistics& stats,
                                                  double wall_s);

  MappingDiagnosticsOptions options_;
  std::deque<DropCount> drop_counts_;
  EventWindow scans_in_, scans_inserted_;  // wall times; inserted values: latency (s)
  EventWindow scans_refused_;              // wall times
  std::size_t scans_refused_total_ = 0;
  std::string last_refusal_;
  std::map<double, double> arrival_wall_s_;  // by scan stamp, until inserted (bounded)
  double first_scan_wall_s_ = -1.0, last_scan_wall_s_ = -1.0, last_label_wall_s_ = -1.0;
  double waiting_for_pose_since_wall_s_ = -1.0;  // < 0: a scan went in (or none dropped yet)
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
