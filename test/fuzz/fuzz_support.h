// Shared by the libFuzzer harnesses: the readers take file paths, so each input is written to a
// file in memory-backed /dev/shm first. Any exception derived from std::exception is an accepted
// refusal; a crash, a sanitizer report or a hang is a finding.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>

namespace ism_fuzz {

inline std::string writeInput(const std::uint8_t* data, std::size_t size, const std::string& name) {
  const std::string path = "/dev/shm/ism_fuzz_" + std::to_string(::getpid()) + "_" + name;
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

}  // namespace ism_fuzz
