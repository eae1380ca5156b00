// kitti2bag: writes a KITTI raw drive into a rosbag with the same topics, frames and stamps as
// kitti_player (both go through ros_conversions::DriveMessageFactory). No ROS master needed.
//
//   kitti2bag --drive DIR [--calib-dir DIR] --output FILE.bag [--start S] [--duration D]
//             [--gps-sigma-h M] [--gps-sigma-v M] [--gps-every N] [--gps-outage START:DURATION]...
//             [--seed S] [--no-velodyne] [--no-camera]
#include <ros/time.h>
#include <rosbag/bag.h>
#include <rosbag/exceptions.h>
#include <tf2_msgs/TFMessage.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include "gps_degradation_flags.h"
#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/ros/kitti_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace {

using namespace inekf_semantic_mapping;  // NOLINT: a small CLI
namespace conv = ros_conversions;

const char kUsage[] =
    "usage: kitti2bag --drive DIR --output FILE.bag [options]\n"
    "  --drive DIR            <date>_drive_<nnnn>_sync (or _extract) folder\n"
    "  --calib-dir DIR        folder with calib_*.txt (default: the drive's parent)\n"
    "  --output FILE.bag      written atomically (FILE.bag.partial, then renamed)\n"
    "  --start S              skip the first S seconds (default 0)\n"
    "  --duration D           write D seconds (default: to the end)\n"
    "  --gps-sigma-h M        horizontal GPS noise std dev, metres (default 0)\n"
    "  --gps-sigma-v M        vertical GPS noise std dev, metres (default 0)\n"
    "  --gps-every N          keep every N-th GPS fix (default 1)\n"
    "  --gps-outage S:D       no GPS fix for D seconds from S s after the first frame\n"
    "                         (repeatable)\n"
    "  --seed S               GPS noise seed (default 0)\n"
    "  --no-velodyne          leave the point clouds out\n"
    "  --no-camera            leave the color left camera out\n";

struct Arguments {
  std::string drive_dir, calib_dir, output;
  kitti::TimelineOptions timeline;
  kitti::GpsDegradationOptions gps;
};

Arguments parseArguments(const common::CommandLine& cli) {
  using common::UsageError;
  Arguments args;
  args.drive_dir = cli.get("--drive");
  args.calib_dir = cli.get("--calib-dir");
  // Named, it must be there: a mistyped folder dropped the camera with a warning and exit 0.
  if (!args.calib_dir.empty() && !std::filesystem::is_directory(args.calib_dir)) {
    throw UsageError("--calib-dir " + args.calib_dir + ": no such folder");
  }
  args.output = cli.get("--output");
  args.timeline.start_offset_s = cli.getDouble("--start", args.timeline.start_offset_s);
  args.timeline.duration_s = cli.getDouble("--duration", args.timeline.duration_s);
  if (!(args.timeline.start_offset_s >= 0.0)) throw UsageError("--start must be >= 0 s");
  if (!(args.timeline.duration_s > 0.0) && cli.has("--duration")) {
    throw UsageError("--duration must be > 0 s (without it: to the end)");
  }
  tools::readGpsDegradationFlags(cli, &args.gps);
  if (cli.has("--no-velodyne")) args.timeline.velodyne = false;
  if (cli.has("--no-camera")) args.timeline.cameras[2] = false;
  if (args.drive_dir.empty() || args.output.empty()) {
    throw UsageError("--drive and --output are required");
  }
  common::checkOutputPath(args.output);  // before the bag is written, not at its rename
  common::checkOutputsAreNotInputs({args.output}, {args.drive_dir, args.calib_dir});
  return args;
}

// A latched connection so that `rosbag play` republishes /tf_static latched, like a
// StaticTransformBroadcaster.
boost::shared_ptr<ros::M_string> latchedConnectionHeader(const std::string& topic) {
  using Traits = tf2_msgs::TFMessage;
  auto header = boost::make_shared<ros::M_string>();
  (*header)["topic"] = topic;
  (*header)["type"] = ros::message_traits::datatype<Traits>();
  (*header)["md5sum"] = ros::message_traits::md5sum<Traits>();
  (*header)["message_definition"] = ros::message_traits::definition<Traits>();
  (*header)["callerid"] = "/kitti2bag";
  (*header)["latching"] = "1";
  return header;
}

// Whether the progress bar's line is open (printed without its newline): an error message
// ends it first.
bool g_progress_line_open = false;

void printProgress(std::size_t done, std::size_t total) {
  const int width = 40;
  const int filled = total ? static_cast<int>(width * done / total) : width;
  std::fprintf(stderr, "\r[%s%s] %zu/%zu", std::string(filled, '#').c_str(),
               std::string(width - filled, ' ').c_str(), done, total);
  if (done == total) std::fputc('\n', stderr);
  g_progress_line_open = done < total;
  std::fflush(stderr);
}

int run(const Arguments& args) {
  const kitti::RawDrive drive(args.drive_dir, args.calib_dir);
  for (const std::string& part : drive.missingParts()) {
    std::cerr << "kitti2bag: warning: " << drive.driveDir() << " has no " << part
              << ": not written\n";
  }
  for (const std::string& warning : drive.frameWarnings()) {
    std::cerr << "kitti2bag: warning: " << warning << "\n";
  }
  for (const std::string& step : drive.stampWarnings()) {
    std::cerr << "kitti2bag: warning: " << step << " (the bag is written in stamp order)\n";
  }
  const kitti::TimelineOptions& timeline_options = args.timeline;
  // Before anything is written: a bag of clouds without imu_link -> velo_link maps nothing.
  drive.requireCalibrationFor(timeline_options.velodyne, timeline_options.cameras[2], "--calib-dir",
                              "--no-velodyne / --no-camera");
  conv::DriveMessageFactory factory(drive, args.gps);
  const std::vector<kitti::TimelineEvent> timeline =
      kitti::buildDriveTimeline(drive, timeline_options);
  if (timeline.empty()) throw std::invalid_argument("nothing to write in the chosen window");
  conv::checkTimelineFitsRosTime(drive.driveDir(), timeline.front().stamp_ns,
                                 timeline.back().stamp_ns);

  // Written as FILE.bag.partial (the name the usage documents), renamed when complete; on any
  // error the partial bag is removed.
  std::size_t messages = 0;
  common::commitFileAtomically(
      args.output, args.output + ".partial", [&](const std::string& partial) {
        // rosbag::Bag's destructor closes the file and throws if that fails, which after a
        // failed write (a full disk) would throw during unwinding and abort: on error the bag
        // is closed here, its second failure ignored (the first error is the one to report), and
        // the object released unclosed (the tool exits; commitFileAtomically removes the file).
        auto owned_bag = std::make_unique<rosbag::Bag>(partial, rosbag::bagmode::Write);
        rosbag::Bag& bag = *owned_bag;
        try {
          const ros::Time first = conv::toRosTime(timeline.front().stamp_ns);
          tf2_msgs::TFMessage tf_static;
          tf_static.transforms = factory.staticTransformMessages(first);
          bag.write("/tf_static", first, tf_static, latchedConnectionHeader("/tf_static"));
          ++messages;
          const bool interactive = isatty(STDERR_FILENO);
          for (std::size_t i = 0; i < timeline.size(); ++i) {
            const kitti::TimelineEvent& event = timeline[i];
            const ros::Time stamp = conv::toRosTime(event.stamp_ns);
            switch (event.sensor) {
              case kitti::DriveSensor::kOxts: {
                ScopedTimer timer("kitti2bag/oxts");
                const conv::OxtsMessages oxts = factory.oxtsMessages(event.frame);
                bag.write(bag_topics::kImu, stamp, oxts.imu);
                if (oxts.gps_fix) bag.write(bag_topics::kGpsFix, stamp, *oxts.gps_fix);
                bag.write(bag_topics::kGpsVelocity, stamp, oxts.gps_velocity);
                bag.write(bag_topics::kGroundTruthOdometry, stamp, oxts.ground_truth);
                messages += oxts.gps_fix ? 4 : 3;
                break;
              }
              case kitti::DriveSensor::kVelodyne: {
                ScopedTimer timer("kitti2bag/velodyne");
                bag.write(bag_topics::kVelodyne, stamp, factory.velodyneMessage(event.frame));
                ++messages;
                break;
              }
              case kitti::DriveSensor::kCamera2: {
                ScopedTimer timer("kitti2bag/camera");
                const auto [image, info] = factory.cameraMessages(2, event.frame);
                bag.write(bag_topics::kCameraColorLeftImage, stamp, image);
                bag.write(bag_topics::kCameraColorLeftInfo, stamp, info);
                messages += 2;
                break;
              }
              default:
                break;
            }
            if (interactive ? (i % 20 == 0 || i + 1 == timeline.size())
                            : (i % 1000 == 0 || i + 1 == timeline.size())) {
              printProgress(i + 1, timeline.size());
            }
          }
          bag.close();
        } catch (const std::exception& error) {
          // The progress bar's line ends before the error message (it was glued to it).
          if (g_progress_line_open) std::fputc('\n', stderr);
          try {
            bag.close();
          } catch (const std::exception&) {
          }
          (void)owned_bag.release();
          // rosbag's own errors are the output's (a full disk); any other names its input file
          // (an image of the wrong size) and is passed on as it is.
          if (dynamic_cast<const rosbag::BagException*>(&error) == nullptr) throw;
          throw std::runtime_error("cannot write " + args.output + ": " + error.what());
        }
      });
  std::cerr << "kitti2bag: wrote " << messages << " messages ("
            << kitti::secondsBetween(timeline.front().stamp_ns, timeline.back().stamp_ns)
            << " s) to " << args.output << "\n"
            << TimingRegistry::instance().report();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return common::runCli("kitti2bag", kUsage, [&] {
    const common::CommandLine cli(
        argc, argv,
        tools::withGpsValueFlags({"--drive", "--calib-dir", "--output", "--start", "--duration"}),
        {"--no-velodyne", "--no-camera"}, tools::kGpsRepeatableFlags);
    if (cli.helpRequested()) return common::printUsage(kUsage);
    return run(parseArguments(cli));
  });
}
