// The tools' command-line parser: the input is split into arguments at NUL bytes.
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/cli_args.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::string> args{"tool"};
  std::string current;
  for (std::size_t i = 0; i < size; ++i) {
    if (data[i] == 0) {
      args.push_back(current);
      current.clear();
    } else {
      current.push_back(static_cast<char>(data[i]));
    }
  }
  args.push_back(current);
  std::vector<const char*> argv;
  for (const std::string& arg : args) argv.push_back(arg.c_str());
  try {
    const inekf_semantic_mapping::common::CommandLine cli(
        static_cast<int>(argv.size()), argv.data(), {"--scans", "--resolution", "--max-scans"},
        {"--verbose"}, {"--train"});
    cli.getDouble("--resolution", 0.2);
    cli.getInt("--max-scans", -1);
    cli.getAll("--train");
  } catch (const std::exception&) {
  }
  return 0;
}
