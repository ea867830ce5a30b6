#include "protocol/messages.h"
#include "protocol/chunk_hash.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <limits>

#include "common/codec/byte_rle.h"
#include "common/codec/net_codec.h"

namespace terrane {
namespace {

// Unwraps a built frame into its verified Message.
const wire::Message* message_of(const Frame& f) {
  EXPECT_GE(f.size(), kFrameHeaderBytes);
  const std::size_t len = std::size_t{f[0]} | std::size_t{f[1]} << 8 | std::size_t{f[2]} << 16 | std::size_t{f[3]} << 24;
  EXPECT_EQ(len + kFrameHeaderBytes, f.size());
  auto m = verify_message(std::span<const std::uint8_t>(f.data() + kFrameHeaderBytes, len));
  EXPECT_TRUE(m.ok());
  return m.ok() ? *m : nullptr;
}

TEST(Messages, HelloRoundTrips) {
  const Frame f = build_hello(HelloMsg{kProtocolVersion, "alice", "secret", {}});
  const auto* m = message_of(f);
  ASSERT_EQ(m->body_type(), wire::Body::Hello);
  auto h = parse_hello(*m->body_as_Hello());
  ASSERT_TRUE(h.ok());
  EXPECT_EQ(h->protocol_version, kProtocolVersion);
  EXPECT_EQ(h->client_name, "alice");
  EXPECT_EQ(h->auth_token, "secret");
  EXPECT_EQ(h->resume_token, "");
  // A redirected client echoes its Redirect's token.
  auto r = parse_hello(*message_of(build_hello(HelloMsg{kProtocolVersion, "alice", "", "1/17"}))->body_as_Hello());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->resume_token, "1/17");
  flatbuffers::FlatBufferBuilder fbb;
  const std::string long_token(kMaxResumeTokenBytes + 1, 't');
  fbb.Finish(wire::CreateHelloDirect(fbb, 1, "alice", "", long_token.c_str()));
  EXPECT_EQ(parse_hello(*flatbuffers::GetRoot<wire::Hello>(fbb.GetBufferPointer())).error().code,
            DecodeErrorCode::kOverLimit);
  flatbuffers::FlatBufferBuilder fbb3;
  fbb3.Finish(wire::CreateHelloDirect(fbb3, 1, "alice", "", "1/17\n[forged log line]"));
  EXPECT_EQ(parse_hello(*flatbuffers::GetRoot<wire::Hello>(fbb3.GetBufferPointer())).error().code,
            DecodeErrorCode::kInvalidValue);
  // A name must be printable too (servers log it); UTF-8 beyond ASCII is fine.
  for (const char* name : {"alice\nsession 9 joined", "tab\tbed", "del\x7f"}) {
    flatbuffers::FlatBufferBuilder fbb4;
    fbb4.Finish(wire::CreateHelloDirect(fbb4, 1, name, "", ""));
    const auto bad = parse_hello(*flatbuffers::GetRoot<wire::Hello>(fbb4.GetBufferPointer()));
    ASSERT_FALSE(bad.ok()) << name;
    EXPECT_EQ(bad.error().code, DecodeErrorCode::kInvalidValue);
    EXPECT_NE(std::string(bad.error().detail).find("control character"), std::string::npos);
  }
  EXPECT_TRUE(parse_hello(*message_of(build_hello(HelloMsg{kProtocolVersion, "Zoë ☃", "", {}}))->body_as_Hello()).ok());
}

TEST(Messages, RedirectRoundTripsAndBadOnesAreErrors) {
  const RedirectMsg sent{2, "10.0.0.7", 7778, "1/17"};
  auto r = parse_redirect(*message_of(build_redirect(sent))->body_as_Redirect());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->server_id, 2u);
  EXPECT_EQ(r->host, "10.0.0.7");
  EXPECT_EQ(r->port, 7778);
  EXPECT_EQ(r->token, "1/17");
  auto parse = [](const char* host, std::uint16_t port, const std::string& token) {
    flatbuffers::FlatBufferBuilder fbb;
    fbb.Finish(wire::CreateRedirectDirect(fbb, 2, host, port, token.c_str()));
    return parse_redirect(*flatbuffers::GetRoot<wire::Redirect>(fbb.GetBufferPointer()));
  };
  EXPECT_TRUE(parse("server.example", 1, "").ok());
  EXPECT_EQ(parse(nullptr, 7778, "").error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(parse("", 7778, "").error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(parse("10.0.0.7", 0, "").error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(parse("bad host", 7778, "").error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(parse("bad\nhost", 7778, "").error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(parse(std::string(kMaxRedirectHostBytes + 1, 'h').c_str(), 7778, "").error().code,
            DecodeErrorCode::kOverLimit);
  EXPECT_EQ(parse("10.0.0.7", 7778, std::string(kMaxResumeTokenBytes + 1, 't')).error().code,
            DecodeErrorCode::kOverLimit);
}

TEST(Messages, HelloRejectsMissingOrLongName) {
  flatbuffers::FlatBufferBuilder fbb;
  const std::string long_name(kMaxClientNameBytes + 1, 'x');
  fbb.Finish(wire::CreateHelloDirect(fbb, 1, long_name.c_str(), ""));
  const auto* hello = flatbuffers::GetRoot<wire::Hello>(fbb.GetBufferPointer());
  EXPECT_EQ(parse_hello(*hello).error().code, DecodeErrorCode::kOverLimit);
  flatbuffers::FlatBufferBuilder fbb2;
  fbb2.Finish(wire::CreateHelloDirect(fbb2, 1, nullptr, nullptr));
  EXPECT_EQ(parse_hello(*flatbuffers::GetRoot<wire::Hello>(fbb2.GetBufferPointer())).error().code,
            DecodeErrorCode::kInvalidValue);
}

TEST(Messages, WelcomeRoundTrips) {
  WelcomeMsg w;
  w.server_epoch = 7;
  w.spawn = {1.5f, 60.0f, -3.5f};
  w.materials = {"Air", "Water", "Grass"};
  w.bounds_min_y = -128;
  w.bounds_max_y = 256;
  w.max_view_distance = 1024;
  w.max_full_res_radius = 256;
  w.max_frame_bytes = 1 << 20;
  w.tick_hz = 20;
  w.server_id = 3;
  const Frame f = build_welcome(w);
  const auto* m = message_of(f);
  auto p = parse_welcome(*m->body_as_Welcome());
  ASSERT_TRUE(p.ok()) << p.error().describe();
  EXPECT_EQ(p->server_epoch, 7u);
  EXPECT_EQ(p->server_id, 3u);
  EXPECT_EQ(p->spawn, w.spawn);
  EXPECT_EQ(p->materials, w.materials);
  EXPECT_EQ(p->bounds_max_y, 256);
  EXPECT_EQ(p->tick_hz, 20u);
  EXPECT_FALSE(p->bounded_xz);
  // A border and the defaults travel too; nonsense is refused.
  w.bounded_xz = true;
  w.bounds_min_x = -64;
  w.bounds_max_x = 640;
  w.bounds_min_z = 0;
  w.bounds_max_z = 96;
  w.default_view_distance = 512;
  w.default_full_res_radius = 64;
  const Frame fb = build_welcome(w);
  auto q = parse_welcome(*message_of(fb)->body_as_Welcome());
  ASSERT_TRUE(q.ok()) << q.error().describe();
  EXPECT_EQ(q->bounds().min_x, -64);
  EXPECT_EQ(q->bounds().max_z, 96);
  EXPECT_EQ(q->default_view_distance, 512);
  EXPECT_EQ(q->default_full_res_radius, 64);
  w.bounds_max_z = -5;  // empty
  const Frame bad = build_welcome(w);
  EXPECT_FALSE(parse_welcome(*message_of(bad)->body_as_Welcome()).ok());
  w.bounds_max_z = 96;
  w.default_view_distance = 2048;  // beyond the cap
  const Frame bad2 = build_welcome(w);
  EXPECT_FALSE(parse_welcome(*message_of(bad2)->body_as_Welcome()).ok());
  // The edit rate: absent reads as 0 (unlimited); negative or NaN is refused.
  w.default_view_distance = 512;
  EXPECT_EQ(q->edits_per_second, 0.0f);
  w.edits_per_second = 20;
  w.edit_burst = 40;
  const Frame fr = build_welcome(w);
  auto r = parse_welcome(*message_of(fr)->body_as_Welcome());
  ASSERT_TRUE(r.ok()) << r.error().describe();
  EXPECT_EQ(r->edits_per_second, 20.0f);
  EXPECT_EQ(r->edit_burst, 40u);
  for (const float bad_rate : {-1.0f, std::numeric_limits<float>::quiet_NaN()}) {
    w.edits_per_second = bad_rate;
    const Frame fbad = build_welcome(w);
    EXPECT_FALSE(parse_welcome(*message_of(fbad)->body_as_Welcome()).ok());
  }
}

TEST(Messages, ClientStateRejectsNonFiniteAndOutOfRange) {
  auto parse = [](ClientStateMsg s) {
    const Frame f = build_client_state(s);
    return parse_client_state(*message_of(f)->body_as_ClientState());
  };
  EXPECT_TRUE(parse({{1, 2, 3}, 256, 64}).ok());
  EXPECT_FALSE(parse({{std::numeric_limits<float>::quiet_NaN(), 0, 0}, 256, 64}).ok());
  EXPECT_FALSE(parse({{std::numeric_limits<float>::infinity(), 0, 0}, 256, 64}).ok());
  EXPECT_FALSE(parse({{3e7f, 0, 0}, 256, 64}).ok());
  EXPECT_FALSE(parse({{0, 0, 0}, -1, 64}).ok());
  EXPECT_FALSE(parse({{0, 0, 0}, 256, kMaxWireViewDistance + 1}).ok());
}

Result<EditRequestMsg> parse_edit(const EditRequestMsg& e) {
  const Frame f = build_edit_request(e);
  return parse_edit_request(*message_of(f)->body_as_EditRequest());
}

TEST(Messages, EditRequestsRoundTripAndAreBounded) {
  EditRequestMsg box;
  box.edit_id = 9;
  box.kind = EditKind::kFillBox;
  box.box = {{-4, 0, -4}, {4, 8, 4}};
  box.material = materials::kRock;
  box.occupancy = 200;
  auto b = parse_edit(box);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->edit_id, 9u);
  EXPECT_EQ(b->box, box.box);
  EXPECT_EQ(b->occupancy, 200);

  EditRequestMsg big = box;
  big.box = {{0, 0, 0}, {65, 64, 64}};
  EXPECT_EQ(parse_edit(big).error().code, DecodeErrorCode::kOverLimit);
  EditRequestMsg empty = box;
  empty.box = {{0, 0, 0}, {0, 4, 4}};
  EXPECT_FALSE(parse_edit(empty).ok());
  EditRequestMsg far = box;
  far.box = {{kMaxWireCoordinate, 0, 0}, {kMaxWireCoordinate + 2, 1, 1}};
  EXPECT_FALSE(parse_edit(far).ok());
  EditRequestMsg bad_material = box;
  bad_material.material = 64;
  EXPECT_FALSE(parse_edit(bad_material).ok());

  EditRequestMsg sphere;
  sphere.kind = EditKind::kFillSphere;
  sphere.center = {1.5f, 2.5f, 3.5f};
  sphere.radius = 6;
  sphere.material = materials::kSand;
  auto s = parse_edit(sphere);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->center, sphere.center);
  EXPECT_EQ(s->radius, 6.0f);
  EditRequestMsg huge = sphere;
  huge.radius = kMaxSphereRadius + 1;
  EXPECT_EQ(parse_edit(huge).error().code, DecodeErrorCode::kOverLimit);
  EditRequestMsg nan = sphere;
  nan.radius = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(parse_edit(nan).ok());
  EditRequestMsg zero = sphere;
  zero.radius = 0;
  EXPECT_FALSE(parse_edit(zero).ok());
}

TEST(Messages, SphereEditKindsRoundTripWithTheirRules) {
  auto parse = [](const EditRequestMsg& e) {
    return parse_edit_request(*message_of(build_edit_request(e))->body_as_EditRequest());
  };
  EditRequestMsg e;
  e.edit_id = 4;
  e.center = {1.5f, -2.0f, 3.25f};
  e.radius = 2.5f;
  e.material = materials::kRock;
  e.kind = EditKind::kDig;
  auto d = parse(e);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->kind, EditKind::kDig);
  EXPECT_EQ(d->material, kAir);  // a dig writes Air whatever was asked
  EXPECT_EQ(d->center, e.center);
  e.kind = EditKind::kPaint;
  auto p = parse(e);
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->material, materials::kRock);
  e.material = kAir;
  EXPECT_FALSE(parse(e).ok());  // painting with Air means nothing
  e.kind = EditKind::kSmooth;
  e.occupancy = 0;
  auto sm = parse(e);
  ASSERT_TRUE(sm.ok());
  EXPECT_EQ(sm->occupancy, 128);  // default strength
  EXPECT_EQ(sm->reads(), (Region{sm->bounds().min - Vec3i{1, 1, 1}, sm->bounds().max + Vec3i{1, 1, 1}}));
  e.radius = 40.0f;
  EXPECT_FALSE(parse(e).ok());
}

TEST(Messages, WriteBoxCarriesExactlyItsVoxels) {
  EditRequestMsg e;
  e.edit_id = 8;
  e.kind = EditKind::kWriteBox;
  e.box = {{-3, 5, 7}, {2, 8, 9}};
  for (std::int64_t i = 0; i < e.box.volume(); ++i)
    e.voxels.push_back(i % 2 ? Voxel{} : make_voxel(materials::kSand, static_cast<std::uint8_t>(i * 9)));
  auto w = parse_edit_request(*message_of(build_edit_request(e))->body_as_EditRequest());
  ASSERT_TRUE(w.ok()) << w.error().describe();
  EXPECT_EQ(w->box, e.box);
  EXPECT_EQ(w->voxels, e.voxels);
  // Data for a different box size, a box over the raw limit, no data.
  auto with = [&](Region box, std::span<const Voxel> voxels) {
    std::vector<std::uint8_t> rle;
    byte_rle_encode(voxels, rle);
    flatbuffers::FlatBufferBuilder fbb;
    const wire::Vec3i mn(box.min.x, box.min.y, box.min.z), mx(box.max.x, box.max.y, box.max.z);
    fbb.Finish(wire::CreateEditRequestDirect(fbb, 1, wire::EditKind::WriteBox, &mn, &mx, nullptr, 0, 0, 0, &rle));
    return parse_edit_request(*flatbuffers::GetRoot<wire::EditRequest>(fbb.GetBufferPointer()));
  };
  EXPECT_TRUE(with(e.box, e.voxels).ok());
  EXPECT_FALSE(with(e.box, std::span(e.voxels).first(e.voxels.size() - 1)).ok());
  EXPECT_FALSE(with(Region{{0, 0, 0}, {33, 32, 32}}, std::vector<Voxel>(33 * 32 * 32)).ok());
  EXPECT_FALSE(with(e.box, {}).ok());
}

TEST(Messages, BoxesSpanningTheWholeWireRangeAreOverLimit) {
  // Each side 2^25 voxels: the volume does not fit 64 bits and must
  // saturate, not overflow.
  const Region huge{{-kMaxWireCoordinate, -kMaxWireCoordinate, -kMaxWireCoordinate},
                    {kMaxWireCoordinate, kMaxWireCoordinate, kMaxWireCoordinate}};
  EXPECT_EQ(huge.volume(), std::numeric_limits<std::int64_t>::max());
  auto r = parse_read_box(*message_of(build_read_box(1, huge))->body_as_ReadBox());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, DecodeErrorCode::kOverLimit);
  EditRequestMsg e;
  e.kind = EditKind::kFillBox;
  e.box = huge;
  e.material = materials::kRock;
  EXPECT_FALSE(parse_edit_request(*message_of(build_edit_request(e))->body_as_EditRequest()).ok());
}

TEST(Messages, UnknownEditKindIsRejected) {
  flatbuffers::FlatBufferBuilder fbb;
  const wire::Vec3i mn(0, 0, 0), mx(1, 1, 1);
  fbb.Finish(wire::CreateEditRequest(fbb, 1, static_cast<wire::EditKind>(17), &mn, &mx));
  EXPECT_FALSE(parse_edit_request(*flatbuffers::GetRoot<wire::EditRequest>(fbb.GetBufferPointer())).ok());
}

TEST(Messages, ReadBoxAndItsResultRoundTrip) {
  const Region box{{10, -4, 3}, {14, 0, 9}};
  auto r = parse_read_box(*message_of(build_read_box(12, box))->body_as_ReadBox());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->request_id, 12u);
  EXPECT_EQ(r->box, box);
  EXPECT_FALSE(parse_read_box(*message_of(build_read_box(1, Region{{0, 0, 0}, {64, 64, 64}}))->body_as_ReadBox()).ok());
  std::vector<Voxel> voxels(static_cast<std::size_t>(box.volume()), solid(materials::kGrass));
  voxels[5] = Voxel{};
  auto res = parse_read_box_result(*message_of(build_read_box_result(12, box, voxels))->body_as_ReadBoxResult());
  ASSERT_TRUE(res.ok());
  EXPECT_TRUE(res->error.empty());
  EXPECT_EQ(res->voxels, voxels);
  auto err = parse_read_box_result(*message_of(build_read_box_error(13, box, "not held"))->body_as_ReadBoxResult());
  ASSERT_TRUE(err.ok());
  EXPECT_EQ(err->error, "not held");
  EXPECT_TRUE(err->voxels.empty());
}

TEST(Messages, EditRejectCarriesTheTrueState) {
  auto plain = parse_edit_reject(*message_of(build_edit_reject(3, "no"))->body_as_EditReject());
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(plain->reason, "no");
  EXPECT_TRUE(plain->box.empty());
  const Region box{{0, 0, 0}, {2, 3, 4}};
  std::vector<Voxel> voxels(24, make_voxel(materials::kRock, 99));
  auto full = parse_edit_reject(*message_of(build_edit_reject(3, "outside", box, voxels))->body_as_EditReject());
  ASSERT_TRUE(full.ok());
  EXPECT_EQ(full->box, box);
  EXPECT_EQ(full->voxels, voxels);
  EXPECT_FALSE(full->outcome_unknown);
}

// A rejection says whether the edit was not applied (the default) or may
// have been (outcome_unknown), with or without the true state.
TEST(Messages, EditRejectSaysWhetherItsOutcomeIsUnknown) {
  EXPECT_FALSE(parse_edit_reject(*message_of(build_edit_reject(3, "no"))->body_as_EditReject())->outcome_unknown);
  auto plain = parse_edit_reject(*message_of(build_edit_reject(4, "lost", true))->body_as_EditReject());
  ASSERT_TRUE(plain.ok());
  EXPECT_TRUE(plain->outcome_unknown);
  EXPECT_EQ(plain->reason, "lost");
  const Region box{{0, 0, 0}, {1, 1, 2}};
  std::vector<Voxel> voxels(2, make_voxel(materials::kRock, 99));
  auto full = parse_edit_reject(*message_of(build_edit_reject(5, "lost", box, voxels, true))->body_as_EditReject());
  ASSERT_TRUE(full.ok());
  EXPECT_TRUE(full->outcome_unknown);
  EXPECT_EQ(full->voxels, voxels);
}

TEST(Messages, PresenceIsBoundedAndChecked) {
  std::vector<PresenceEntryMsg> entries;
  for (std::uint32_t i = 0; i < 70; ++i) entries.push_back({i, {static_cast<float>(i), 2.0f, 3.0f}});
  auto p = parse_presence(*message_of(build_presence(entries))->body_as_Presence());
  ASSERT_TRUE(p.ok());
  ASSERT_EQ(p->size(), kMaxPresenceEntries);  // the builder keeps the first 64
  EXPECT_EQ((*p)[63].client_id, 63u);
  // Names round-trip (and an entry without one reads as empty).
  entries = {{7, {1, 2, 3}, "digger"}, {8, {4, 5, 6}, ""}};
  p = parse_presence(*message_of(build_presence(entries))->body_as_Presence());
  ASSERT_TRUE(p.ok());
  ASSERT_EQ(p->size(), 2u);
  EXPECT_EQ((*p)[0].name, "digger");
  EXPECT_EQ((*p)[1].name, "");
  // A name a Hello could not carry is refused: a control character, or
  // longer than 64 bytes.
  for (const std::string& name : {std::string("two\nlines"), std::string(65, 'n')}) {
    flatbuffers::FlatBufferBuilder named;
    const wire::Vec3f at(1, 2, 3);
    std::vector<flatbuffers::Offset<wire::PresenceEntry>> one{
        wire::CreatePresenceEntry(named, 1, &at, named.CreateString(name))};
    named.Finish(wire::CreatePresenceDirect(named, &one));
    EXPECT_FALSE(parse_presence(*flatbuffers::GetRoot<wire::Presence>(named.GetBufferPointer())).ok()) << name;
  }
  flatbuffers::FlatBufferBuilder fbb;
  std::vector<flatbuffers::Offset<wire::PresenceEntry>> bad;
  const wire::Vec3f inf(std::numeric_limits<float>::infinity(), 0, 0);
  bad.push_back(wire::CreatePresenceEntry(fbb, 1, &inf));
  fbb.Finish(wire::CreatePresenceDirect(fbb, &bad));
  EXPECT_FALSE(parse_presence(*flatbuffers::GetRoot<wire::Presence>(fbb.GetBufferPointer())).ok());
}

// Holdings carry a claimable form per chunk: Full, Mip 1..3 or Empty
// (protocol/holding.h); an approximate form (Estimate, a horizon's) or an
// unknown number is a protocol error.
TEST(Messages, HoldingsCarryClaimableFormsOnly) {
  auto round_trip = [](std::vector<HeldChunkMsg> v) {
    return parse_holdings(*message_of(build_holdings(v))->body_as_Holdings());
  };
  const std::vector<HeldChunkMsg> good = {{{1, -2, 3}, {HoldingForm::kFull, 5}},
                                          {{4, 5, 6}, {HoldingForm::kMip2, 7}},
                                          {{-7, 0, 9}, {HoldingForm::kEmpty, 0}}};
  auto r = round_trip(good);
  ASSERT_TRUE(r.ok()) << r.error().describe();
  ASSERT_EQ(r->size(), 3u);
  for (std::size_t i = 0; i < good.size(); ++i) {
    EXPECT_EQ((*r)[i].chunk_pos, good[i].chunk_pos);
    EXPECT_EQ((*r)[i].holding, good[i].holding);
  }
  for (const int form : {5, 6, 7, 8, 255}) {
    auto bad = round_trip({{{0, 0, 0}, {static_cast<HoldingForm>(form), 1}}});
    ASSERT_FALSE(bad.ok()) << "form " << form;
    EXPECT_NE(bad.error().describe().find("form not 0..4"), std::string::npos) << bad.error().describe();
  }
  EXPECT_FALSE(round_trip({{{kMaxWireCoordinate, 0, 0}, {HoldingForm::kFull, 1}}}).ok());
}

TEST(Messages, UpdateBatchCarriesRevisions) {
  const std::vector<std::uint8_t> data(5, 2);
  const ChunkRevisionMsg revs[2] = {{{1, 2, 3}, 4}, {{-1, 0, 7}, 9}};
  auto b = parse_update_batch(*message_of(build_update_batch(12, data, revs))->body_as_UpdateBatch());
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->tick, 12u);
  ASSERT_EQ(b->revisions.size(), 2u);
  EXPECT_EQ(b->revisions[1].chunk_pos, (Vec3i{-1, 0, 7}));
  EXPECT_EQ(b->revisions[1].revision, 9u);
  EXPECT_FALSE(parse_update_batch(*message_of(build_update_batch(12, data, {}))->body_as_UpdateBatch()).ok());
}

// The gathered builders make the bytes of the copying ones whatever the
// data's length (the padding after it varies with it) and however it is
// split into owned and shared segments.
TEST(Messages, GatheredBatchesAreTheCopiedOnesByteForByte) {
  auto shared = std::make_shared<std::vector<std::uint8_t>>(OutFrame::kMinSharedBytes + 3);
  for (std::size_t i = 0; i < shared->size(); ++i) (*shared)[i] = static_cast<std::uint8_t>(i * 7);
  const ChunkRevisionMsg revs[3] = {{{1, 2, 3}, 4}, {{-1, 0, 7}, 9}, {{5, 5, 5}, 1ull << 50}};
  for (std::size_t owned = 0; owned < 9; ++owned) {
    for (const bool with_shared : {false, true}) {
      OutFrame data;
      std::vector<std::uint8_t> flat;
      for (std::size_t i = 0; i < owned; ++i) data.owned_tail().push_back(static_cast<std::uint8_t>(i + 1));
      flat = data.owned_tail();
      if (with_shared) {
        data.append_shared(*shared, shared);
        data.append(std::vector<std::uint8_t>(owned, 0xAB));
        flat.insert(flat.end(), shared->begin(), shared->end());
        flat.insert(flat.end(), owned, 0xAB);
      }
      OutFrame records;
      records.append(flat);
      if (with_shared) records.append_shared(*shared, shared);
      std::vector<std::uint8_t> records_flat = flat;
      if (with_shared) records_flat.insert(records_flat.end(), shared->begin(), shared->end());

      const OutFrame update = gather_update_batch(77, std::move(data), revs);
      EXPECT_EQ(update.flatten(), build_update_batch(77, flat, revs)) << owned << " " << with_shared;
      EXPECT_EQ(update.shared_bytes(), with_shared ? shared->size() : 0u);
      const OutFrame stream = gather_stream_batch(std::move(records));
      EXPECT_EQ(stream.flatten(), build_stream_batch(records_flat)) << owned << " " << with_shared;
      // The message type is read from the first segment alone.
      const auto first = stream.first_segment();
      EXPECT_EQ(flatbuffers::GetRoot<wire::Message>(first.data() + kFrameHeaderBytes)->body_type(),
                wire::Body::StreamBatch);
      EXPECT_EQ(flatbuffers::GetRoot<wire::Message>(update.first_segment().data() + kFrameHeaderBytes)->body_type(),
                wire::Body::UpdateBatch);
    }
  }
}

TEST(Messages, SmallMessagesRoundTrip) {
  EXPECT_EQ(message_of(build_ping(5))->body_as_Ping()->nonce(), 5u);
  EXPECT_EQ(message_of(build_pong(6))->body_as_Pong()->nonce(), 6u);
  EXPECT_EQ(message_of(build_edit_ack(3, 99))->body_as_EditAck()->tick(), 99u);
  EXPECT_EQ(message_of(build_edit_reject(3, "no"))->body_as_EditReject()->reason()->str(), "no");
  EXPECT_EQ(parse_disconnect(*message_of(build_disconnect("bye"))->body_as_Disconnect()).value(), "bye");
  auto h = parse_chunk_hash(*message_of(build_chunk_hash({{1, 2, 3}, 4, 5}))->body_as_ChunkHash());
  ASSERT_TRUE(h.ok());
  EXPECT_EQ(h->hash, 5u);
  auto r = parse_chunk_hash_request(*message_of(build_chunk_hash_request({7, 8, 9}))->body_as_ChunkHashRequest());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(*r, (Vec3i{7, 8, 9}));
}

TEST(Messages, LongStringsAreClippedByBuilders) {
  const std::string reason(1000, 'r');
  auto d = parse_disconnect(*message_of(build_disconnect(reason))->body_as_Disconnect());
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->size(), kMaxReasonBytes);
}

TEST(Messages, EveryTruncatedFrameBodyFailsVerification) {
  EditRequestMsg e;
  e.kind = EditKind::kFillSphere;
  e.center = {1, 2, 3};
  e.radius = 4;
  e.material = 3;
  const Frame f = build_edit_request(e);
  const std::span<const std::uint8_t> body(f.data() + kFrameHeaderBytes, f.size() - kFrameHeaderBytes);
  for (std::size_t n = 0; n < body.size(); ++n) EXPECT_FALSE(verify_message(body.first(n)).ok()) << n;
}

// The definition (PROTOCOL.md): FNV-1a 64 over the revision's 8 bytes,
// little-endian, then every voxel's material and occupancy bytes, x fastest,
// then z, then y. The implementation takes Air rows and chunks in one step;
// it must give this value.
std::uint64_t chunk_hash_by_the_book(const Chunk& c, std::uint64_t revision) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  auto byte = [&](std::uint8_t b) {
    h ^= b;
    h *= 0x100000001b3ull;
  };
  for (int i = 0; i < 8; ++i) byte(static_cast<std::uint8_t>(revision >> (8 * i)));
  for (int y = 0; y < kChunkSize; ++y)
    for (int z = 0; z < kChunkSize; ++z)
      for (int x = 0; x < kChunkSize; ++x) {
        const Voxel v = c.get(x, y, z);
        byte(v.material);
        byte(v.occupancy);
      }
  return h;
}

TEST(ChunkHash, EqualsTheDefinitionByteByByte) {
  Chunk c;
  EXPECT_EQ(chunk_hash(&c, 9), chunk_hash_by_the_book(c, 9));
  // Solid rows, Air rows and scattered voxels.
  c.modify(Region{{0, 0, 0}, {32, 5, 32}}, [](Vec3i, Voxel) { return make_voxel(materials::kRock, 255); });
  for (int i = 0; i < 300; ++i) c.set({(i * 7) % 32, 5 + (i * 13) % 27, (i * 11) % 32}, make_voxel(materials::kSand, static_cast<std::uint8_t>(i)));
  for (const std::uint64_t rev : {std::uint64_t{0}, std::uint64_t{12345}, ~std::uint64_t{0}})
    EXPECT_EQ(chunk_hash(&c, rev), chunk_hash_by_the_book(c, rev)) << rev;
}

// A row of one voxel is hashed from a table of its values per low byte of
// the hash (filled as met, a few voxels per thread): it must give the
// definition's value for any hash before it, for more voxels than the
// tables keep, met again after being dropped.
TEST(ChunkHash, RowsOfOneVoxelEqualTheDefinitionForAnyHashBefore) {
  auto by_the_book = [](std::uint64_t h, const Voxel* row) {
    for (int x = 0; x < kChunkSize; ++x) {
      h = (h ^ row[x].material) * 0x100000001b3ull;
      h = (h ^ row[x].occupancy) * 0x100000001b3ull;
    }
    return h;
  };
  std::uint64_t seed = 0x9e3779b97f4a7c15ull;
  auto next = [&] {
    seed ^= seed << 13, seed ^= seed >> 7, seed ^= seed << 17;
    return seed;
  };
  std::array<Voxel, kChunkSize> row;
  for (int round = 0; round < 3; ++round)
    for (int m = 0; m < 24; ++m) {
      // Air itself (m = 0), Air with an occupancy (22), a material past the
      // 6 bits (23: any byte can be hashed); each met again in the next
      // round, after 23 others.
      const Voxel v = m == 22 ? Voxel{kAir, 5}
                              : Voxel{static_cast<Material>(m == 23 ? 200 : m), static_cast<std::uint8_t>(m * 37)};
      row.fill(v);
      for (int i = 0; i < 600; ++i) {
        const std::uint64_t h = i < 256 ? (next() & ~std::uint64_t{0xff}) | static_cast<std::uint64_t>(i) : next();
        ASSERT_EQ(hash_row(h, row.data()), by_the_book(h, row.data())) << m << " " << i;
      }
      // One voxel different anywhere, in either byte: not a row of one voxel.
      for (int x = 0; x < 2 * kChunkSize; ++x) {
        row.fill(v);
        if (x < kChunkSize) row[x].occupancy ^= 1;
        else row[x - kChunkSize].material ^= 1;
        const std::uint64_t h = next();
        ASSERT_EQ(hash_row(h, row.data()), by_the_book(h, row.data())) << m << " " << x;
      }
      // Rows repeating two or four voxels (every 8-byte word alike).
      for (const int period : {2, 4}) {
        for (int x = 0; x < kChunkSize; ++x)
          row[x] = x % period == period - 1 ? Voxel{v.material, static_cast<std::uint8_t>(v.occupancy + 1)} : v;
        const std::uint64_t h = next();
        ASSERT_EQ(hash_row(h, row.data()), by_the_book(h, row.data())) << m << " " << period;
      }
    }
}

TEST(ChunkHash, DependsOnVoxelsAndRevision) {
  Chunk a;
  EXPECT_EQ(chunk_hash(&a, 3), chunk_hash(nullptr, 3));
  // Nothing (all Air) is hashed in one multiplication: the same value as
  // hashing the Air voxel by voxel, at any revision.
  for (const std::uint64_t rev : {std::uint64_t{0}, std::uint64_t{1}, std::uint64_t{255}, std::uint64_t{1} << 40, ~std::uint64_t{0}})
    EXPECT_EQ(chunk_hash(&a, rev), chunk_hash(nullptr, rev)) << rev;
  EXPECT_NE(chunk_hash(nullptr, 3), chunk_hash(nullptr, 4));
  Chunk b;
  b.set({1, 2, 3}, make_voxel(materials::kRock, 200));
  EXPECT_NE(chunk_hash(&b, 3), chunk_hash(nullptr, 3));
  Chunk c;
  c.set({1, 2, 3}, make_voxel(materials::kRock, 201));
  EXPECT_NE(chunk_hash(&b, 3), chunk_hash(&c, 3));
  c.set({1, 2, 3}, make_voxel(materials::kRock, 200));
  EXPECT_EQ(chunk_hash(&b, 3), chunk_hash(&c, 3));
}

TEST(ChunkHash, GoldenValueOfAnEmptyChunk) {
  // Pinned so both sides (and future versions) agree on the definition.
  EXPECT_EQ(chunk_hash(nullptr, 0), chunk_hash(nullptr, 0));
  const std::uint64_t empty0 = chunk_hash(nullptr, 0);
  // FNV-1a of 8 zero bytes then 65536 zero bytes.
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (int i = 0; i < 8 + 2 * 32768; ++i) h *= 0x100000001b3ull;
  EXPECT_EQ(empty0, h);
}

}  // namespace
}  // namespace terrane
