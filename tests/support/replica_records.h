// Test support: a replica takes stream records (a Full record of given
// payload bytes, or a writer's batch) through the wire's StreamBatch frame,
// as the client library does (the record's payload span is the bytes
// given). Header-only.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <functional>
#include <vector>

#include "client/replica.h"
#include "protocol/messages.h"
#include "protocol/stream_batch.h"

namespace terrane::testing_support {

// The records w holds, through the wire's frame, to r. known: the
// receiver's payloads decoded before, as the client passes them (records
// it skipped are counted in *skipped); check: run on each record first.
inline void take_records(Replica& r, StreamBatchWriter& w, const KnownPayloadFn& known = nullptr,
                         int* skipped = nullptr, const std::function<void(const StreamRecord&)>& check = nullptr) {
  const Frame f = w.finish().flatten();
  auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
  ASSERT_TRUE(m.ok());
  auto records = parse_stream_batch(*(*m)->body_as_StreamBatch());
  ASSERT_TRUE(records.ok());
  StreamDecodeScratch s;
  ASSERT_TRUE(decode_stream_batch(
                  *records, s,
                  [&](const StreamRecord& rec) -> Status {
                    if (check) check(rec);
                    if (rec.known) {
                      EXPECT_EQ(rec.voxels, nullptr);
                      if (skipped != nullptr) ++*skipped;
                    }
                    r.apply_stream_record(rec);
                    return Ok{};
                  },
                  known)
                  .ok());
}

inline void take_full(Replica& r, Vec3i cp, std::uint64_t revision, const std::vector<std::uint8_t>& payload) {
  StreamBatchWriter w;
  w.add(StreamRecordKind::kFull, cp, revision, payload);
  take_records(r, w, nullptr, nullptr, [&](const StreamRecord& rec) {
    EXPECT_TRUE(std::equal(rec.payload.begin(), rec.payload.end(), payload.begin(), payload.end()));
  });
}

}  // namespace terrane::testing_support
