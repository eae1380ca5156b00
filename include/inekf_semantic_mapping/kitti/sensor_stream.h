// One sensor folder of a KITTI raw drive (oxts, velodyne_points, image_00..03): line n of its
// timestamps.txt stamps its data file data/%010d<ext> numbered n. A frame the recorder dropped
// keeps its line, blank, and has no file (2011_09_26_drive_0009_sync's velodyne frames 177-180):
// the frames here are the lines with both a stamp and a file, each with its file's number, so
// that a stamp never goes with another frame's data.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace kitti {

struct SensorStream {
  std::string name;                           // "oxts", "velodyne_points", "image_02", ...
  std::string dir;                            // <drive>/<name>
  bool present = false;                       // dir/data and dir/timestamps.txt exist
  std::vector<std::int64_t> stamps_ns;        // per frame, from timestamps.txt
  std::vector<std::size_t> file_numbers;      // per frame: its data file's number (its line)
  std::vector<std::int64_t> start_stamps_ns;  // per frame, velodyne timestamps_start.txt, or empty
  std::vector<std::int64_t> end_stamps_ns;    // per frame, velodyne timestamps_end.txt, or empty
  std::string extension;                      // of the data files: ".txt", ".bin", ".png"
  // What was left out, one message each naming the folder and the file numbers: lines and files
  // that do not make a frame, a timestamps_start/_end.txt that does not fit.
  std::vector<std::string> warnings;

  std::size_t size() const { return stamps_ns.size(); }
  // <dir>/data/%010d<extension> of the frame's file number.
  std::string framePath(std::size_t frame) const;
  // The frame's file number as its file is named ("0000000177").
  std::string fileStem(std::size_t frame) const;
  // The frame whose stamp is nearest stamp_ns, if within max_offset_ns of it (-1 otherwise, and
  // for a stream without frames). Stamps need not be sorted.
  std::ptrdiff_t nearestFrame(std::int64_t stamp_ns, std::int64_t max_offset_ns) const;
  // For each of `other_stamps_ns` (another stream's frames), the frame of this stream that goes
  // with it, or -1: each frame goes to the stamp nearest it if within max_offset_ns, and a stamp
  // that two frames pick keeps the nearer. Pairs a drive's OXTS frames with its scans whatever
  // their rates (an _extract drive's OXTS at 100 Hz) and wherever the recorder dropped frames.
  std::vector<std::ptrdiff_t> framesAt(const std::vector<std::int64_t>& other_stamps_ns,
                                       std::int64_t max_offset_ns) const;
};

// Reads the folder dir (name: the stream's name). Not present when dir/data is not a folder.
// Throws KittiFormatError naming the file when dir/data has no timestamps.txt beside it, on a
// timestamp line that does not parse (path:line), and when data files are there but none is
// numbered as a line of timestamps.txt (data/%010d<ext> from 0). The data files' extension is
// the most common one in data/.
SensorStream readSensorStream(const std::string& dir, const std::string& name);

}  // namespace kitti
}  // namespace inekf_semantic_mapping
