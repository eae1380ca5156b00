// The one exception type of the KITTI readers: its message names the file, the line (when there
// is one) and what was wrong, so a user can fix the data without a debugger.
#pragma once

#include <stdexcept>
#include <string>

namespace inekf_semantic_mapping {
namespace kitti {

class KittiFormatError : public std::runtime_error {
 public:
  // line_number <= 0: the problem is not tied to one line (missing file, bad size, counts).
  KittiFormatError(const std::string& file, int line_number, const std::string& what_was_wrong)
      : std::runtime_error(formatMessage(file, line_number, what_was_wrong)),
        file_(file),
        line_number_(line_number) {}
  KittiFormatError(const std::string& file, const std::string& what_was_wrong)
      : KittiFormatError(file, 0, what_was_wrong) {}

  const std::string& file() const { return file_; }
  int lineNumber() const { return line_number_; }

 private:
  static std::string formatMessage(const std::string& file, int line_number,
                                   const std::string& what_was_wrong) {
    std::string message = file;
    if (line_number > 0) message += ":" + std::to_string(line_number);
    return message + ": " + what_was_wrong;
  }

  std::string file_;
  int line_number_;
};

}  // namespace kitti
}  // namespace inekf_semantic_mapping
