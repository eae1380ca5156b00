#include "inekf_semantic_mapping/kitti/sensor_stream.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace fs = std::filesystem;

namespace {

// "177-180, 300, and 12 more": runs of consecutive numbers, at most max_runs of them.
std::string numberRuns(const std::vector<std::size_t>& numbers, std::size_t max_runs = 5) {
  std::string text;
  std::size_t runs = 0, i = 0;
  while (i < numbers.size()) {
    std::size_t j = i;
    while (j + 1 < numbers.size() && numbers[j + 1] == numbers[j] + 1) ++j;
    if (runs == max_runs) {
      text += ", and " + std::to_string(numbers.size() - i) + " more";
      break;
    }
    text += (text.empty() ? "" : ", ") + std::to_string(numbers[i]);
    if (j > i) text += "-" + std::to_string(numbers[j]);
    ++runs;
    i = j + 1;
  }
  return text;
}

// The number of a data file named as KITTI names them (%010d), or nullopt: framePath() rebuilds
// the name from the number, so "000001.bin" is no frame.
std::optional<std::size_t> fileNumber(const fs::path& path) {
  const std::string stem = path.stem().string();
  if (stem.size() != 10 || !std::all_of(stem.begin(), stem.end(), [](char c) {
        return std::isdigit(static_cast<unsigned char>(c)) != 0;
      })) {
    return std::nullopt;
  }
  return static_cast<std::size_t>(std::stoull(stem));
}

// timestamps_start.txt / timestamps_end.txt: per frame, or empty with a warning when it does not
// fit timestamps.txt line for line.
std::vector<std::int64_t> readExtraStamps(const fs::path& path, const SensorStream& stream,
                                          std::vector<std::string>* warnings) {
  if (!fs::is_regular_file(path)) return {};
  const std::vector<std::optional<std::int64_t>> extra = readTimestampLines(path.string());
  std::vector<std::int64_t> stamps;
  for (const std::size_t number : stream.file_numbers) {
    if (number >= extra.size() || !extra[number]) {
      warnings->push_back(path.string() + ":" + std::to_string(number + 1) +
                          ": no stamp for frame " + std::to_string(number) +
                          ", which timestamps.txt stamps: the file is not used");
      return {};
    }
    stamps.push_back(*extra[number]);
  }
  return stamps;
}

}  // namespace

std::string SensorStream::framePath(std::size_t frame) const {
  return dir + "/data/" + fileStem(frame) + extension;
}

std::string SensorStream::fileStem(std::size_t frame) const {
  char name[32];
  std::snprintf(name, sizeof(name), "%010zu", file_numbers.at(frame));
  return name;
}

std::ptrdiff_t SensorStream::nearestFrame(std::int64_t stamp_ns, std::int64_t max_offset_ns) const {
  std::ptrdiff_t best = -1;
  std::int64_t best_offset = max_offset_ns;
  for (std::size_t i = 0; i < stamps_ns.size(); ++i) {
    const std::int64_t offset =
        stamps_ns[i] > stamp_ns ? stamps_ns[i] - stamp_ns : stamp_ns - stamps_ns[i];
    if (offset <= best_offset && (best < 0 || offset < best_offset)) {
      best = static_cast<std::ptrdiff_t>(i);
      best_offset = offset;
    }
  }
  return best;
}

std::vector<std::ptrdiff_t> SensorStream::framesAt(const std::vector<std::int64_t>& other_stamps_ns,
                                                   std::int64_t max_offset_ns) const {
  std::vector<std::ptrdiff_t> frame_at(other_stamps_ns.size(), -1);
  std::vector<std::int64_t> offset_at(other_stamps_ns.size(), 0);
  for (std::size_t frame = 0; frame < size(); ++frame) {
    std::ptrdiff_t nearest = -1;
    std::int64_t nearest_offset = 0;
    for (std::size_t k = 0; k < other_stamps_ns.size(); ++k) {
      const std::int64_t offset = std::abs(other_stamps_ns[k] - stamps_ns[frame]);
      if (nearest < 0 || offset < nearest_offset) {
        nearest = static_cast<std::ptrdiff_t>(k);
        nearest_offset = offset;
      }
    }
    if (nearest < 0 || nearest_offset > max_offset_ns) continue;
    const auto k = static_cast<std::size_t>(nearest);
    if (frame_at[k] < 0 || nearest_offset < offset_at[k]) {
      frame_at[k] = static_cast<std::ptrdiff_t>(frame);
      offset_at[k] = nearest_offset;
    }
  }
  return frame_at;
}

SensorStream readSensorStream(const std::string& dir, const std::string& name) {
  SensorStream stream;
  stream.name = name;
  stream.dir = dir;
  const fs::path data_dir = fs::path(dir) / "data";
  const fs::path timestamps = fs::path(dir) / "timestamps.txt";
  if (!fs::is_directory(data_dir)) return stream;
  if (!fs::is_regular_file(timestamps)) {
    throw KittiFormatError(dir, "has data/ but no timestamps.txt");
  }
  stream.present = true;
  const std::vector<std::optional<std::int64_t>> lines = readTimestampLines(timestamps.string());

  // The most common extension is the sensor's format; its files named as frames, by number.
  struct Files {
    std::size_t count = 0;  // however named
    std::vector<std::size_t> numbers;
    std::string example;
  };
  std::map<std::string, Files> by_extension;
  for (const auto& entry : fs::directory_iterator(data_dir)) {
    if (!entry.is_regular_file()) continue;
    Files& files = by_extension[entry.path().extension().string()];
    ++files.count;
    files.example = entry.path().filename().string();
    if (const auto number = fileNumber(entry.path())) files.numbers.push_back(*number);
  }
  Files data;
  for (auto& [extension, files] : by_extension) {
    if (files.count > data.count) {
      data = std::move(files);
      stream.extension = extension;
    }
  }
  std::vector<std::size_t>& files = data.numbers;
  std::sort(files.begin(), files.end());

  std::vector<std::size_t> dropped, without_file, without_stamp, beyond;
  auto file = files.begin();
  for (std::size_t n = 0; n < lines.size(); ++n) {
    while (file != files.end() && *file < n) ++file;
    const bool has_file = file != files.end() && *file == n;
    if (lines[n] && has_file) {
      stream.stamps_ns.push_back(*lines[n]);
      stream.file_numbers.push_back(n);
    } else if (lines[n]) {
      without_file.push_back(n);
    } else {
      (has_file ? without_stamp : dropped).push_back(n);
    }
  }
  for (; file != files.end(); ++file) {
    if (*file >= lines.size()) beyond.push_back(*file);
  }
  if (stream.stamps_ns.empty() && data.count > 0) {
    const bool no_stamp = std::none_of(lines.begin(), lines.end(),
                                       [](const auto& stamp) { return stamp.has_value(); });
    throw KittiFormatError(
        no_stamp ? timestamps.string() : dir,
        no_stamp ? "no stamp for the " + std::to_string(data.count) + " files in data/"
                 : std::to_string(data.count) + " files in data/ (" + stream.extension + ", e.g. " +
                       data.example +
                       ") but none named as a line of timestamps.txt numbers it (data/%010d" +
                       stream.extension + ", from 0)");
  }
  const auto warn = [&stream](const std::vector<std::size_t>& numbers, const std::string& why) {
    if (numbers.empty()) return;
    stream.warnings.push_back(stream.dir + ": frame" + (numbers.size() > 1 ? "s " : " ") +
                              numberRuns(numbers) + " left out: " + why);
  };
  warn(dropped, "blank in timestamps.txt and no data file (dropped by the recorder)");
  warn(without_file, "in timestamps.txt but no data/ file");
  warn(without_stamp, "a data/ file but a blank line in timestamps.txt");
  warn(beyond, "a data/ file but no line in timestamps.txt");

  for (const char* which : {"start", "end"}) {
    const fs::path extra = fs::path(dir) / (std::string("timestamps_") + which + ".txt");
    (std::string(which) == "start" ? stream.start_stamps_ns : stream.end_stamps_ns) =
        readExtraStamps(extra, stream, &stream.warnings);
  }
  return stream;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
