// Expectations on the KITTI readers' errors, shared by the unit and the real-data tests.
#pragma once

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/errors.h"

namespace inekf_semantic_mapping {
namespace test {

// Runs `body`, expects a KittiFormatError whose message contains every fragment.
template <typename Body>
void expectFormatError(Body body, const std::vector<std::string>& fragments) {
  try {
    body();
    ADD_FAILURE() << "expected KittiFormatError";
  } catch (const kitti::KittiFormatError& error) {
    for (const auto& fragment : fragments) {
      EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos)
          << "'" << fragment << "' not in: " << error.what();
    }
  }
}

}  // namespace test
}  // namespace inekf_semantic_mapping
