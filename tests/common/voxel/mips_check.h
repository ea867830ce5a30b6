// The voxel tests' check that a chunk's stored mips are the levels its level 0
// gives when the chunk is built afresh (Chunk::from_box).
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "common/voxel/chunk.h"

namespace terrane::test_mips {

inline void expect_mips_as_rebuilt(const Chunk& chunk, const Chunk& fresh, const std::string& where) {
  for (int level = 1; level < kMipLevels; ++level) {
    Box a, b;
    chunk.read_level(level, a);
    fresh.read_level(level, b);
    ASSERT_TRUE(a == b) << where << " level " << level;
  }
}

}  // namespace terrane::test_mips
