// Atomic file writes: write a temporary file beside the target, then rename it over the target,
// so that a reader sees either the old file or the complete new one, never half a file. On any
// failure the temporary is removed and the target is left as it was.
//
//   common::writeTextAtomically("out/poses.txt", text);
//   common::writeStreamAtomically("out/map.ot", [&](std::ostream& out) { tree.write(out); });
//   common::commitFileAtomically("out/img.png", [&](const std::string& tmp) {
//     if (!cv::imwrite(tmp, image)) throw std::runtime_error("cannot encode " + tmp);
//   });
//
// Header-only, standard library only (usable from the ROS-free core libraries and the tools).
#pragma once

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

namespace inekf_semantic_mapping {
namespace common {

// A write that could not be completed; the target is unchanged and no temporary is left.
// what(): "cannot write '<path>': <reason>".
class AtomicWriteError : public std::runtime_error {
 public:
  AtomicWriteError(const std::string& path, const std::string& reason)
      : std::runtime_error("cannot write '" + path + "': " + reason),
        path_(path),
        reason_(reason) {}

  const std::string& path() const { return path_; }
  // E.g. "cannot create '<tmp>': No such file or directory", "write failed (disk full?)",
  // "rename failed: ...".
  const std::string& reason() const { return reason_; }

 private:
  std::string path_;
  std::string reason_;
};

// A temporary path beside `path` (same directory, so the rename is atomic), unique per process
// and per call: <dir>/.tmp.<pid>.<n>.<filename>. The file's extension stays at the end (tools
// such as cv::imwrite pick the format from it).
inline std::string temporaryPathFor(const std::string& path) {
  static std::atomic<unsigned long> counter{0};
  const std::filesystem::path target(path);
  const std::string name = ".tmp." + std::to_string(static_cast<long>(::getpid())) + "." +
                           std::to_string(counter.fetch_add(1)) + "." + target.filename().string();
  return (target.parent_path() / name).string();
}

// Whether two output paths name one file, however spelt ("a.txt", "./d/../a.txt").
inline bool isSameOutput(const std::string& a, const std::string& b) {
  return std::filesystem::absolute(a).lexically_normal() ==
         std::filesystem::absolute(b).lexically_normal();
}

// Throws AtomicWriteError unless `path` can be written atomically: not a directory, in an
// existing directory this process may write to. A tool calls it for each output before its long
// work, so that a mistyped output folder fails in a second, not after the whole run.
inline void checkOutputPath(const std::string& path) {
  if (path.empty()) throw AtomicWriteError(path, "empty output path");
  namespace fs = std::filesystem;
  if (fs::is_directory(path)) throw AtomicWriteError(path, "is a directory");
  const fs::path parent = fs::absolute(path).parent_path();
  if (!fs::is_directory(parent)) {
    throw AtomicWriteError(path, "no directory " + parent.string());
  }
  if (::access(parent.c_str(), W_OK) != 0) {
    throw AtomicWriteError(path, "directory " + parent.string() + ": " + std::strerror(errno));
  }
}

// The same for a set of outputs, which must also be distinct files (one named twice would be
// written twice, the second replacing the first).
inline void checkOutputPaths(const std::vector<std::string>& paths) {
  for (std::size_t i = 0; i < paths.size(); ++i) {
    checkOutputPath(paths[i]);
    for (std::size_t j = 0; j < i; ++j) {
      if (isSameOutput(paths[i], paths[j])) {
        throw AtomicWriteError(paths[i],
                               "given as two outputs (the second would replace the first)");
      }
    }
  }
}

// Throws AtomicWriteError when an output file is an existing input file or an existing file of an
// input folder, or an output is an input folder itself: the tool would destroy what it reads (an
// output typed over an input replaced it, with exit status 0). A new file beside the inputs is not
// refused. Output folders: checkOutputFolderIsNotInAnInput.
inline void checkOutputsAreNotInputs(const std::vector<std::string>& outputs,
                                     const std::vector<std::string>& inputs) {
  namespace fs = std::filesystem;
  for (const std::string& output : outputs) {
    std::error_code error;
    if (output.empty() || !fs::exists(output, error)) continue;
    const fs::path out = fs::canonical(output, error);
    if (error) continue;
    for (const std::string& input : inputs) {
      if (input.empty() || !fs::exists(input, error)) continue;
      const fs::path in = fs::canonical(input, error);
      if (error) continue;
      if (out == in) {
        throw AtomicWriteError(output, "is an input (" + input + "): writing it would destroy it");
      }
      const bool below =
          fs::is_directory(in) && !fs::is_directory(out) &&
          std::mismatch(in.begin(), in.end(), out.begin(), out.end()).first == in.end();
      if (below) {
        throw AtomicWriteError(
            output, "is in the input folder " + input + ": writing it would replace what is read");
      }
    }
  }
}

// Throws AtomicWriteError when an output folder, new or not, is or lies in an input folder (an
// output folder inside a drive overwrote its images); the same answer on every run.
inline void checkOutputFolderIsNotInAnInput(const std::string& dir,
                                            const std::vector<std::string>& inputs) {
  namespace fs = std::filesystem;
  std::error_code error;
  const fs::path out = fs::weakly_canonical(dir, error);
  if (error || dir.empty()) return;
  for (const std::string& input : inputs) {
    if (input.empty() || !fs::is_directory(input, error)) continue;
    const fs::path in = fs::canonical(input, error);
    if (error) continue;
    if (std::mismatch(in.begin(), in.end(), out.begin(), out.end()).first == in.end()) {
      throw AtomicWriteError(
          dir, "is in the input folder " + input + ": give an output folder outside the inputs");
    }
  }
}

// An output folder: an existing one this process may write into, or a new one whose parent is
// there to make it in.
inline void checkOutputDirectory(const std::string& dir) {
  namespace fs = std::filesystem;
  if (dir.empty()) throw AtomicWriteError(dir, "empty output folder");
  if (fs::exists(dir) && !fs::is_directory(dir)) throw AtomicWriteError(dir, "is not a folder");
  const fs::path place =
      fs::is_directory(dir) ? fs::path(dir) : fs::absolute(dir).lexically_normal().parent_path();
  if (!fs::is_directory(place)) throw AtomicWriteError(dir, "no directory " + place.string());
  if (::access(place.c_str(), W_OK) != 0) {
    throw AtomicWriteError(dir, "directory " + place.string() + ": " + std::strerror(errno));
  }
}

// Calls write(tmp_path), which must create and fully write tmp_path (throwing on failure), then
// renames tmp_path over path. If write throws, the temporary is removed and the exception
// propagates unchanged; if the rename fails, the temporary is removed and AtomicWriteError is
// thrown. tmp_path must be in path's directory (temporaryPathFor gives one).
inline void commitFileAtomically(const std::string& path, const std::string& tmp_path,
                                 const std::function<void(const std::string& tmp_path)>& write) {
  std::error_code ignored;
  try {
    write(tmp_path);
  } catch (...) {
    std::filesystem::remove(tmp_path, ignored);
    throw;
  }
  std::error_code error;
  std::filesystem::rename(tmp_path, path, error);
  if (error) {
    std::filesystem::remove(tmp_path, ignored);
    throw AtomicWriteError(path, "rename failed: " + error.message());
  }
}

// The same with tmp_path = temporaryPathFor(path).
inline void commitFileAtomically(const std::string& path,
                                 const std::function<void(const std::string& tmp_path)>& write) {
  commitFileAtomically(path, temporaryPathFor(path), write);
}

// Writes tmp_path through a binary std::ofstream handed to body; errors name `path`, the file
// the caller asked for. Throws AtomicWriteError if tmp_path cannot be created or the stream has
// failed after body or after the flush; an exception thrown by body propagates unchanged.
inline void writeStreamTo(const std::string& path, const std::string& tmp_path,
                          const std::function<void(std::ostream&)>& body) {
  std::ofstream out(tmp_path, std::ios::binary | std::ios::trunc);
  if (!out) {
    throw AtomicWriteError(path, "cannot create '" + tmp_path + "': " + std::strerror(errno));
  }
  body(out);
  if (out) out.flush();
  if (out) out.close();
  if (!out) throw AtomicWriteError(path, "write failed (disk full?)");
}

// Writes path through a binary std::ofstream handed to body. Throws AtomicWriteError if the
// temporary cannot be created or the stream has failed after body or after the flush; an
// exception thrown by body propagates unchanged. Either way the target is unchanged.
inline void writeStreamAtomically(const std::string& path,
                                  const std::function<void(std::ostream&)>& body) {
  if (path.empty()) throw AtomicWriteError(path, "empty output path");
  commitFileAtomically(path,
                       [&](const std::string& tmp_path) { writeStreamTo(path, tmp_path, body); });
}

// The outputs of one run that appear together or not at all (a tool's trajectory, its truth
// and its states; a CSV and its overlay): each is written to a temporary beside its target when
// added, and commit() renames them all. Without commit() (an exception on the way) the
// temporaries are removed and every target stays as it was.
//   common::AtomicFileSet outputs;
//   outputs.addStream("poses.txt", [&](std::ostream& out) { ... });
//   outputs.add("overlay.png", [&](const std::string& tmp) { cv::imwrite(tmp, image) ...; });
//   outputs.commit();
// A target that is a directory is refused when added; a rename within a directory then fails
// only on a filesystem fault, the one case that can leave part of the set (the target is named).
class AtomicFileSet {
 public:
  AtomicFileSet() = default;
  AtomicFileSet(const AtomicFileSet&) = delete;
  AtomicFileSet& operator=(const AtomicFileSet&) = delete;
  ~AtomicFileSet() { discard(); }

  void add(const std::string& path, const std::function<void(const std::string& tmp_path)>& write) {
    // A target a rename cannot replace (a directory) or a place without its directory, refused
    // before any of the set is written.
    checkOutputPath(path);
    // Two outputs of one set on one file: the later rename would silently replace the earlier.
    for (const auto& staged : staged_) {
      if (isSameOutput(staged.first, path)) {
        throw AtomicWriteError(path, "given as two outputs (the second would replace the first)");
      }
    }
    staged_.push_back({path, temporaryPathFor(path)});
    write(staged_.back().second);
  }
  void addStream(const std::string& path, const std::function<void(std::ostream&)>& body) {
    add(path, [&](const std::string& tmp_path) { writeStreamTo(path, tmp_path, body); });
  }
  void commit() {
    for (std::size_t i = 0; i < staged_.size(); ++i) {
      std::error_code error;
      std::filesystem::rename(staged_[i].second, staged_[i].first, error);
      if (error) {
        const std::string failed = staged_[i].first;
        staged_.erase(staged_.begin(), staged_.begin() + static_cast<std::ptrdiff_t>(i));
        discard();
        throw AtomicWriteError(failed, "rename failed: " + error.message());
      }
    }
    staged_.clear();
  }

 private:
  void discard() {
    std::error_code ignored;
    for (const auto& [path, tmp_path] : staged_) std::filesystem::remove(tmp_path, ignored);
    staged_.clear();
  }

  std::vector<std::pair<std::string, std::string>> staged_;  // target, temporary
};

// Writes size bytes from data to path atomically.
inline void writeBytesAtomically(const std::string& path, const void* data, std::size_t size) {
  writeStreamAtomically(path, [&](std::ostream& out) {
    if (size > 0) out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  });
}

// Writes text to path atomically.
inline void writeTextAtomically(const std::string& path, const std::string& text) {
  writeBytesAtomically(path, text.data(), text.size());
}

}  // namespace common
}  // namespace inekf_semantic_mapping
