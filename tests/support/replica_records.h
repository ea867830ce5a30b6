// Test support: a replica takes a Full stream record of given payload
// bytes, through the wire's StreamBatch frame, as the client library does
// (the record's payload span is the bytes given). Header-only.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "client/replica.h"
#include "protocol/messages.h"
#include "protocol/stream_batch.h"

namespace terrane::testing_support {

inline void take_full(Replica& r, Vec3i cp, std::uint64_t revision, const std::vector<std::uint8_t>& payload) {
  StreamBatchWriter w;
  w.add(StreamRecordKind::kFull, cp, revision, payload);
  const Frame f = w.finish().flatten();
  auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
  ASSERT_TRUE(m.ok());
  auto records = parse_stream_batch(*(*m)->body_as_StreamBatch());
  ASSERT_TRUE(records.ok());
  StreamDecodeScratch s;
  ASSERT_TRUE(decode_stream_batch(*records, s, [&](const StreamRecord& rec) -> Status {
                EXPECT_TRUE(std::equal(rec.payload.begin(), rec.payload.end(), payload.begin(), payload.end()));
                r.apply_stream_record(rec);
                return Ok{};
              }).ok());
}

}  // namespace terrane::testing_support
