// Every flag a command-line tool's usage names is one its parser accepts: the usage is what users
// read, and a flag it documents but the parser refuses ("unknown argument") is a broken promise
// that no other test sees. The flags are read from each tool's --help: every flag of the synopsis
// (the lines before the first option description) and every flag that starts an option
// description ("  --flag   what it does"); flags named in the prose (another tool's, or a glob
// such as --gps-*) are not the tool's own. Each is then given to the tool followed by two
// unknown flags: a value flag takes the first as its value, a switch does not, and either way the
// parser must get past it and stop at the unknown one. Nothing runs: the parse fails first.
#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "test_data.h"

namespace {

std::vector<std::string> toolPaths() {
  std::ifstream in(ISM_TOOL_PATHS_FILE);
  std::vector<std::string> paths;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) paths.push_back(line);
  }
  return paths;
}

std::set<std::string> documentedFlags(const std::string& usage) {
  const std::regex description(R"(^ {1,4}((?:--[a-z][a-z0-9-]*(?![a-z0-9*-])(?:, )?)+))");
  const std::regex flag(R"(--[a-z][a-z0-9-]*(?![a-z0-9*-]))");
  std::set<std::string> flags;
  bool synopsis = true;
  std::istringstream lines(usage);
  for (std::string line; std::getline(lines, line);) {
    std::smatch match;
    const bool describes = std::regex_search(line, match, description);
    if (describes) synopsis = false;
    if (!synopsis && !describes) continue;
    const std::string text = synopsis ? line : match[1].str();
    for (std::sregex_iterator it(text.begin(), text.end(), flag), end; it != end; ++it) {
      flags.insert(it->str());
    }
  }
  return flags;
}

TEST(ToolUsage, FindsTheFlagsOfASynopsisAndOfTheOptionDescriptionsOnly) {
  const std::string usage =
      "usage: tool --input DIR [--rate HZ] [--quiet | --loud]\n"
      "  --input     a folder (see other_tool --not-mine)\n"
      "  --rate, --hz  the rate\n"
      "  --gps-*     globs are not flags\n"
      "              --also-not-mine in a wrapped line\n";
  const std::set<std::string> expected{"--input", "--rate", "--quiet", "--loud", "--hz"};
  EXPECT_EQ(documentedFlags(usage), expected);
}

TEST(ToolUsage, EveryDocumentedFlagIsAccepted) {
  const std::vector<std::string> tools = toolPaths();
  ASSERT_GE(tools.size(), 9u) << "tool list " << ISM_TOOL_PATHS_FILE;
  for (const std::string& tool : tools) {
    const auto [help_status, usage] = inekf_semantic_mapping::test::runCommand(tool + " --help");
    EXPECT_EQ(help_status, 0) << tool << " --help";
    const std::set<std::string> flags = documentedFlags(usage);
    EXPECT_GE(flags.size(), 2u) << tool << ": no flags found in its usage:\n" << usage;
    for (const std::string& flag : flags) {
      const auto [status, output] =
          inekf_semantic_mapping::test::runCommand(tool + " " + flag + " --zz-probe --zz-probe");
      EXPECT_EQ(status, 2) << tool << " " << flag << ":\n" << output;
      EXPECT_NE(output.find("unknown argument '--zz-probe'"), std::string::npos)
          << tool << ": its usage names " << flag << " but the parser refuses it:\n"
          << output.substr(0, output.find('\n'));
    }
  }
}

}  // namespace
