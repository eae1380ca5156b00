// Command-line parsing shared by the offline tools: `--flag value` options, `--switch` flags,
// repeatable options, -h/--help, and typed getters that reject malformed numbers.
//
//   int main(int argc, char** argv) {
//     return common::runCli("tool", kUsage, [&] {
//       const common::CommandLine cli(argc, argv, {"--input", "--rate"}, {"--quiet"});
//       if (cli.helpRequested()) return common::printUsage(kUsage);
//       const std::string input = cli.require("--input");
//       const double rate = cli.getDouble("--rate", 10.0);
//       ...
//       return 0;
//     });
//   }
//
// A UsageError (bad command line) makes runCli print "tool: <message>", a blank line and the
// usage to stderr and return 2; any other std::exception prints "tool: <message>" and returns 1.
//
// Header-only, standard library only.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace common {

// A malformed command line (unknown flag, missing value, bad number, missing required flag...).
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class CommandLine {
 public:
  // value_flags take the next argument as their value (whatever it looks like, so that negative
  // numbers work); switch_flags take none; repeatable_flags are value flags that may be given
  // more than once (read them with getAll). Anything else, a value flag at the end of the line,
  // or a non-repeatable flag given twice throws UsageError. Parsing stops at -h/--help (what
  // follows it is not checked), as the tools print their usage and exit there.
  CommandLine(int argc, const char* const* argv, const std::vector<std::string>& value_flags,
              const std::vector<std::string>& switch_flags = {},
              const std::vector<std::string>& repeatable_flags = {}) {
    for (int i = 1; i < argc; ++i) {
      const std::string flag = argv[i];
      if (flag == "-h" || flag == "--help") {
        help_ = true;
        return;
      }
      const bool repeatable = contains(repeatable_flags, flag);
      const bool takes_value = repeatable || contains(value_flags, flag);
      if (!takes_value && !contains(switch_flags, flag)) {
        throw UsageError("unknown argument '" + flag + "'");
      }
      if (!repeatable && values_.count(flag)) throw UsageError(flag + " given more than once");
      if (!takes_value) {
        values_[flag].emplace_back();
        continue;
      }
      if (i + 1 >= argc) throw UsageError(flag + " needs a value");
      values_[flag].emplace_back(argv[++i]);
    }
  }

  // -h or --help was given.
  bool helpRequested() const { return help_; }

  // The flag (value, switch or repeatable) was given.
  bool has(const std::string& flag) const { return values_.count(flag) > 0; }

  // The flag's value, or fallback when it was not given.
  std::string get(const std::string& flag, const std::string& fallback = "") const {
    const auto it = values_.find(flag);
    return it == values_.end() ? fallback : it->second.back();
  }

  // The flag's value; UsageError "--flag is required" when it was not given.
  std::string require(const std::string& flag) const {
    if (!has(flag)) throw UsageError(flag + " is required");
    return get(flag);
  }

  // The values of those of `flags` that were given (a tool's inputs, to check its outputs
  // against).
  std::vector<std::string> valuesOf(const std::vector<std::string>& flags) const {
    std::vector<std::string> values;
    for (const std::string& flag : flags) {
      for (const std::string& value : getAll(flag)) values.push_back(value);
    }
    return values;
  }

  // Every value of a repeatable flag, in command-line order (empty when not given).
  std::vector<std::string> getAll(const std::string& flag) const {
    const auto it = values_.find(flag);
    return it == values_.end() ? std::vector<std::string>{} : it->second;
  }

  // Typed values; a malformed one throws UsageError naming the flag and the text.
  double getDouble(const std::string& flag, double fallback) const {
    return has(flag) ? parseDouble(flag, get(flag)) : fallback;
  }
  double requireDouble(const std::string& flag) const { return parseDouble(flag, require(flag)); }
  int getInt(const std::string& flag, int fallback) const {
    return has(flag) ? parseInt(flag, get(flag)) : fallback;
  }
  std::uint64_t getUint64(const std::string& flag, std::uint64_t fallback) const {
    return has(flag) ? parseUint64(flag, get(flag)) : fallback;
  }
  // An on/off flag written 0 or 1: "--flip expects 0 or 1, got '7'".
  bool getBool(const std::string& flag, bool fallback) const {
    if (!has(flag)) return fallback;
    const std::string text = get(flag);
    if (text != "0" && text != "1") throw UsageError(flag + " expects 0 or 1, got '" + text + "'");
    return text == "1";
  }

  // A finite number, the whole text (no trailing characters): "--rate expects a number, got
  // 'abc'".
  static double parseDouble(const std::string& flag, const std::string& text) {
    double value = 0.0;
    if (!parseFinite(text, &value)) {
      throw UsageError(flag + " expects a number, got '" + text + "'");
    }
    return value;
  }

  // A number with an integer value in int's range ("3", "3.0" and "3e0" are 3; "3.5" is not).
  static int parseInt(const std::string& flag, const std::string& text) {
    double value = 0.0;
    if (!parseFinite(text, &value) || value != std::floor(value) ||
        value < std::numeric_limits<int>::min() || value > std::numeric_limits<int>::max()) {
      throw UsageError(flag + " expects an integer, got '" + text + "'");
    }
    return static_cast<int>(value);
  }

  // A non-negative integer in decimal digits (seeds): "--seed expects a non-negative integer".
  static std::uint64_t parseUint64(const std::string& flag, const std::string& text) {
    std::size_t used = 0;
    std::uint64_t value = 0;
    const bool digits = !text.empty() && text.find_first_not_of("0123456789") == std::string::npos;
    try {
      if (digits) value = std::stoull(text, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (!digits || used != text.size()) {
      throw UsageError(flag + " expects a non-negative integer, got '" + text + "'");
    }
    return value;
  }

 private:
  static bool contains(const std::vector<std::string>& list, const std::string& flag) {
    return std::find(list.begin(), list.end(), flag) != list.end();
  }

  // True when the whole of text is a finite number (std::stod syntax).
  static bool parseFinite(const std::string& text, double* value) {
    std::size_t used = 0;
    try {
      *value = std::stod(text, &used);
    } catch (const std::exception&) {
      return false;
    }
    return used > 0 && used == text.size() && std::isfinite(*value);
  }

  std::map<std::string, std::vector<std::string>> values_;
  bool help_ = false;
};

// Prints the usage to stdout (for -h/--help) and returns 0, the exit status.
inline int printUsage(const char* usage) {
  std::cout << usage;
  return 0;
}

// Runs a tool's main body: its return value is the exit status; a UsageError prints
// "NAME: message\n\n<usage>" to stderr and returns 2; any other std::exception prints
// "NAME: message\n" and returns 1.
inline int runCli(const char* name, const char* usage, const std::function<int()>& body) {
  try {
    return body();
  } catch (const UsageError& error) {
    std::cerr << name << ": " << error.what() << "\n\n" << usage;
    return 2;
  } catch (const std::exception& error) {
    std::cerr << name << ": " << error.what() << "\n";
    return 1;
  }
}

}  // namespace common
}  // namespace inekf_semantic_mapping
