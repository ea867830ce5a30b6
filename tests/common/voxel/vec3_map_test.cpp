#include "common/voxel/vec3_map.h"

#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <string>
#include <unordered_map>

namespace terrane {
namespace {

// The map must agree with std::unordered_map under any mix of inserts,
// assignments, lookups and erasures, through growth, tombstones and
// rebuilds that shrink it.
TEST(Vec3iMap, AgreesWithAStandardMapUnderRandomOperations) {
  std::mt19937 rng(7);
  Vec3iMap<std::string> m;
  std::unordered_map<Vec3i, std::string, Vec3iHash> ref;
  std::uniform_int_distribution<int> coord(-20, 20), op(0, 9);
  for (int round = 0; round < 200000; ++round) {
    // Phases: mostly inserting, then mostly erasing, so the table grows and
    // fills with tombstones.
    const bool inserting = (round / 20000) % 2 == 0;
    const Vec3i k{coord(rng), coord(rng) / 4, coord(rng)};
    const int o = op(rng);
    if (o < (inserting ? 6 : 2)) {
      const std::string v = std::to_string(round);
      const auto [it, fresh] = m.try_emplace(k, v);
      const auto [rit, rfresh] = ref.try_emplace(k, v);
      ASSERT_EQ(fresh, rfresh);
      ASSERT_EQ(it->first, k);
      ASSERT_EQ(it->second, rit->second);
    } else if (o < 7) {
      ASSERT_EQ(m.erase(k), ref.erase(k));
    } else if (o < 8) {
      m.insert_or_assign(k, "a" + std::to_string(round));
      ref.insert_or_assign(k, "a" + std::to_string(round));
    } else {
      auto it = m.find(k);
      auto rit = ref.find(k);
      ASSERT_EQ(it == m.end(), rit == ref.end());
      if (rit != ref.end()) {
        ASSERT_EQ(it->second, rit->second);
      }
      ASSERT_EQ(m.count(k), ref.count(k));
    }
    ASSERT_EQ(m.size(), ref.size());
  }
  std::size_t seen = 0;
  for (const auto& [k, v] : m) {
    ASSERT_EQ(ref.at(k), v);
    ++seen;
  }
  EXPECT_EQ(seen, ref.size());
}

TEST(Vec3iMap, EraseWhileIteratingVisitsEachElementOnce) {
  Vec3iMap<int> m;
  for (int i = 0; i < 5000; ++i) m[Vec3i{i, -i, i % 7}] = i;
  std::unordered_map<Vec3i, int, Vec3iHash> visited;
  for (auto it = m.begin(); it != m.end();) {
    ++visited[it->first];
    it = it->second % 3 == 0 ? m.erase(it) : std::next(it);
  }
  EXPECT_EQ(visited.size(), 5000u);
  for (const auto& [k, n] : visited) EXPECT_EQ(n, 1) << k.x;
  EXPECT_EQ(m.size(), 5000u - 1667u);
  for (const auto& [k, v] : m) EXPECT_NE(v % 3, 0);
  // Erased keys are gone, kept ones found, and the tombstones are reused.
  EXPECT_EQ(m.count(Vec3i{0, 0, 0}), 0u);
  EXPECT_EQ(m.at(Vec3i{1, -1, 1}), 1);
  for (int i = 0; i < 5000; i += 3) m.try_emplace(Vec3i{i, -i, i % 7}, -i);
  EXPECT_EQ(m.size(), 5000u);
  EXPECT_EQ(m.at(Vec3i{3, -3, 3}), -3);
  EXPECT_THROW(m.at(Vec3i{9999, 0, 0}), std::out_of_range);
}

TEST(Vec3iMap, AScanInPartsVisitsEachElementOnce) {
  Vec3iMap<int> m;
  for (int i = 0; i < 3000; ++i) m[Vec3i{i, 2 * i, -i}] = i;
  for (int i = 0; i < 3000; i += 4) m.erase(Vec3i{i, 2 * i, -i});  // tombstones are skipped
  std::unordered_map<Vec3i, int, Vec3iHash> visited;
  const std::size_t slots = m.slot_count();
  ASSERT_GE(slots, m.size());
  // Parts of uneven sizes, the last past the end (clipped).
  for (std::size_t from = 0, step = 1; from < slots; from += step, step = step * 3 + 1)
    m.for_each_in_slots(from, from + step, [&](Vec3i k, int v) {
      ++visited[k];
      EXPECT_EQ(v, k.x);
    });
  EXPECT_EQ(visited.size(), m.size());
  for (const auto& [k, n] : visited) {
    EXPECT_EQ(n, 1) << k.x;
    EXPECT_NE(k.x % 4, 0) << k.x;
  }
  Vec3iMap<int> empty;
  EXPECT_EQ(empty.slot_count(), 0u);
  empty.for_each_in_slots(0, 10, [&](Vec3i, int) { ADD_FAILURE(); });
}

TEST(Vec3iMap, OwnsMoveOnlyValuesAndDestroysEachOnce) {
  auto alive = std::make_shared<int>(0);
  struct Counted {
    std::shared_ptr<int> n;
    explicit Counted(std::shared_ptr<int> c) : n(std::move(c)) { ++*n; }
    Counted(Counted&& o) noexcept : n(std::move(o.n)) {}
    Counted(const Counted&) = delete;
    ~Counted() {
      if (n) --*n;
    }
  };
  {
    Vec3iMap<std::unique_ptr<Counted>> m;
    for (int i = 0; i < 1000; ++i) m.try_emplace(Vec3i{i, 0, 0}, std::make_unique<Counted>(alive));
    EXPECT_EQ(*alive, 1000);
    for (int i = 0; i < 1000; i += 2) m.erase(Vec3i{i, 0, 0});
    EXPECT_EQ(*alive, 500);
    Vec3iMap<std::unique_ptr<Counted>> moved(std::move(m));
    EXPECT_EQ(*alive, 500);
    EXPECT_TRUE(m.empty());  // NOLINT: a moved-from map is empty
    moved.clear();
    EXPECT_EQ(*alive, 0);
    moved.try_emplace(Vec3i{1, 2, 3}, std::make_unique<Counted>(alive));
  }
  EXPECT_EQ(*alive, 0);
}

}  // namespace
}  // namespace terrane
