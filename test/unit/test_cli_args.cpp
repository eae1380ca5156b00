// common/cli_args.h: the command-line parser the offline tools share.
#include <gtest/gtest.h>

#include <initializer_list>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/cli_args.h"

using namespace inekf_semantic_mapping::common;  // NOLINT: test

namespace {

const std::vector<std::string> kValues = {"--input", "--rate", "--count", "--seed", "--flip"};
const std::vector<std::string> kSwitches = {"--quiet", "--no-lidar"};
const std::vector<std::string> kRepeatable = {"--outage"};

// Parses `args` (without the program name) with the flags above.
CommandLine parse(std::initializer_list<const char*> args) {
  std::vector<const char*> argv = {"tool"};
  argv.insert(argv.end(), args.begin(), args.end());
  return CommandLine(static_cast<int>(argv.size()), argv.data(), kValues, kSwitches, kRepeatable);
}

// The UsageError message of parsing `args` and then calling `use` (empty if none is thrown).
template <typename Use>
std::string usageError(std::initializer_list<const char*> args, Use use) {
  try {
    use(parse(args));
  } catch (const UsageError& e) {
    return e.what();
  }
  return "";
}
std::string usageError(std::initializer_list<const char*> args) {
  return usageError(args, [](const CommandLine&) {});
}

}  // namespace

TEST(CliArgs, ValuesAndDefaults) {
  const CommandLine cli = parse({"--input", "a.txt", "--rate", "2.5", "--count", "-3"});
  EXPECT_FALSE(cli.helpRequested());
  EXPECT_TRUE(cli.has("--input"));
  EXPECT_EQ(cli.get("--input"), "a.txt");
  EXPECT_EQ(cli.require("--input"), "a.txt");
  EXPECT_DOUBLE_EQ(cli.getDouble("--rate", 1.0), 2.5);
  EXPECT_EQ(cli.getInt("--count", 7), -3);  // a value may look like a flag or a negative number
  // Absent: the defaults.
  EXPECT_FALSE(cli.has("--seed"));
  EXPECT_EQ(cli.get("--seed", "dflt"), "dflt");
  EXPECT_EQ(cli.get("--seed"), "");
  EXPECT_EQ(cli.getUint64("--seed", 42u), 42u);
  EXPECT_DOUBLE_EQ(parse({}).getDouble("--rate", 10.0), 10.0);
  EXPECT_EQ(parse({}).getInt("--count", 7), 7);
  EXPECT_EQ(parse({"--input", "--rate"}).get("--input"), "--rate");
  EXPECT_EQ(parse({"--seed", "18446744073709551615"}).getUint64("--seed", 0),
            18446744073709551615ull);
  EXPECT_EQ(parse({"--count", "4.0"}).getInt("--count", 0), 4);
}

TEST(CliArgs, RequiredFlagMissing) {
  EXPECT_EQ(usageError({}, [](const CommandLine& c) { c.require("--input"); }),
            "--input is required");
  EXPECT_EQ(usageError({}, [](const CommandLine& c) { c.requireDouble("--rate"); }),
            "--rate is required");
}

TEST(CliArgs, UnknownFlagMissingValueAndRepeatsAreUsageErrors) {
  EXPECT_EQ(usageError({"--bogus", "1"}), "unknown argument '--bogus'");
  EXPECT_EQ(usageError({"positional"}), "unknown argument 'positional'");
  EXPECT_EQ(usageError({"--input"}), "--input needs a value");
  EXPECT_EQ(usageError({"--input", "a", "--input", "b"}), "--input given more than once");
  EXPECT_EQ(usageError({"--quiet", "--quiet"}), "--quiet given more than once");
}

TEST(CliArgs, BadNumbersAreRejected) {
  auto rate = [](const CommandLine& c) { c.getDouble("--rate", 0); };
  auto count = [](const CommandLine& c) { c.getInt("--count", 0); };
  auto seed = [](const CommandLine& c) { c.getUint64("--seed", 0); };
  EXPECT_EQ(usageError({"--rate", "abc"}, rate), "--rate expects a number, got 'abc'");
  EXPECT_EQ(usageError({"--rate", "3x"}, rate), "--rate expects a number, got '3x'");
  EXPECT_NE(usageError({"--rate", ""}, rate), "");
  EXPECT_NE(usageError({"--rate", "nan"}, rate), "");
  EXPECT_NE(usageError({"--rate", "inf"}, rate), "");
  EXPECT_NE(usageError({"--rate", "1e999"}, rate), "");
  EXPECT_EQ(usageError({"--rate", "-1.5e-3"}, rate), "");
  EXPECT_EQ(usageError({"--count", "3x"}, count), "--count expects an integer, got '3x'");
  EXPECT_EQ(usageError({"--count", "2.5"}, count), "--count expects an integer, got '2.5'");
  EXPECT_NE(usageError({"--count", "1e10"}, count), "");  // beyond int
  EXPECT_EQ(usageError({"--seed", "-1"}, seed), "--seed expects a non-negative integer, got '-1'");
  EXPECT_NE(usageError({"--seed", "3x"}, seed), "");
  EXPECT_NE(usageError({"--seed", "99999999999999999999"}, seed), "");  // beyond 64 bits
  EXPECT_THROW(CommandLine::parseDouble("--x", "1.0.0"), UsageError);
  // On/off flags: 0 or 1 only (--flip 7 was taken as on).
  auto flip = [](const CommandLine& c) { c.getBool("--flip", false); };
  EXPECT_TRUE(parse({"--flip", "1"}).getBool("--flip", false));
  EXPECT_FALSE(parse({"--flip", "0"}).getBool("--flip", true));
  EXPECT_TRUE(parse({}).getBool("--flip", true));
  EXPECT_EQ(usageError({"--flip", "7"}, flip), "--flip expects 0 or 1, got '7'");
  EXPECT_NE(usageError({"--flip", "yes"}, flip), "");
}

TEST(CliArgs, Switches) {
  const CommandLine cli = parse({"--no-lidar", "--input", "x"});
  EXPECT_TRUE(cli.has("--no-lidar"));
  EXPECT_FALSE(cli.has("--quiet"));
  EXPECT_EQ(cli.get("--input"), "x");
  // A switch takes no value: what follows is the next flag.
  EXPECT_EQ(usageError({"--quiet", "1"}), "unknown argument '1'");
}

TEST(CliArgs, RepeatableFlag) {
  const CommandLine cli = parse({"--outage", "10:5", "--input", "x", "--outage", "30:2"});
  EXPECT_TRUE(cli.has("--outage"));
  EXPECT_EQ(cli.getAll("--outage"), (std::vector<std::string>{"10:5", "30:2"}));
  EXPECT_TRUE(parse({}).getAll("--outage").empty());
  EXPECT_EQ(usageError({"--outage"}), "--outage needs a value");
}

TEST(CliArgs, Help) {
  EXPECT_TRUE(parse({"--help"}).helpRequested());
  EXPECT_TRUE(parse({"--input", "a", "-h"}).helpRequested());
  EXPECT_TRUE(parse({"-h", "--bogus"}).helpRequested());  // parsing stops at the help flag
  EXPECT_EQ(parse({"--input", "--help"}).get("--input"), "--help");  // a value, not help
  EXPECT_EQ(usageError({"--bogus", "--help"}), "unknown argument '--bogus'");
}

TEST(CliArgs, RunCliMapsErrorsToExitStatuses) {
  std::ostringstream captured;
  std::streambuf* old = std::cerr.rdbuf(captured.rdbuf());
  const int usage = runCli("tool", "usage: tool --input X\n",
                           []() -> int { throw UsageError("--input is required"); });
  const int failure =
      runCli("tool", "usage\n", []() -> int { throw std::runtime_error("disk on fire"); });
  const int ok = runCli("tool", "usage\n", [] { return 0; });
  std::cerr.rdbuf(old);
  EXPECT_EQ(usage, 2);
  EXPECT_EQ(failure, 1);
  EXPECT_EQ(ok, 0);
  EXPECT_EQ(captured.str(),
            "tool: --input is required\n\nusage: tool --input X\ntool: disk on fire\n");
}
