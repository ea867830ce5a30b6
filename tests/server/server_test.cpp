// The server in-process, spoken to over real sockets on 127.0.0.1 with a
// minimal blocking peer built on protocol/messages.h; and edit application.
#include "server/server.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <sqlite3.h>
#include <spdlog/sinks/ostream_sink.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <tuple>
#include <numbers>
#include <map>
#include <optional>
#include <tuple>
#include <thread>

#include "common/codec/net_codec.h"
#include "common/codec/bit_io.h"
#include "common/world/coarse_image.h"
#include "common/world/horizon.h"
#include "common/world/sqlite_store.h"
#include "common/world/view.h"
#include "server/world/edits.h"
#include "server/base/log.h"
#include "tests/support/eventually.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

using testing_support::msg;
using testing_support::RawPeer;
using testing_support::ServerTest;

TEST_F(ServerTest, WelcomeDescribesTheWorld) {
  start();
  RawPeer p(server_->port());
  ASSERT_TRUE(p.connected());
  ASSERT_TRUE(p.send(build_hello(HelloMsg{kProtocolVersion, "t", "", {}})));
  auto f = p.next_of(wire::Body::Welcome);
  ASSERT_TRUE(f.has_value());
  auto w = parse_welcome(*msg(*f).body_as_Welcome());
  ASSERT_TRUE(w.ok()) << w.error().describe();
  EXPECT_EQ(w->protocol_version, kProtocolVersion);
  EXPECT_EQ(w->tick_hz, 60u);
  EXPECT_EQ(w->materials.size(), default_material_names().size());
  EXPECT_GE(w->server_epoch, 2u);  // bumped by the start
}

// A version-1 client's Hello (the Hello table and its union id are the
// same in every version) is answered with a Disconnect it can read (union
// id 3 in every version) naming both versions.
TEST_F(ServerTest, AnotherVersionsHelloIsToldWhyInADisconnectItCanRead) {
  start();
  for (const std::uint32_t version : {1u, kProtocolVersion + 5}) {
    RawPeer p(server_->port());
    const Frame hello = build_hello(HelloMsg{version, "t", "", {}});
    auto sent = verify_message(std::span<const std::uint8_t>(hello).subspan(kFrameHeaderBytes));
    ASSERT_TRUE(sent.ok());
    EXPECT_EQ(static_cast<int>((*sent)->body_type()), 1);
    ASSERT_TRUE(p.send(hello));
    auto f = p.next_of(wire::Body::Disconnect);
    ASSERT_TRUE(f.has_value());
    EXPECT_EQ(static_cast<int>(msg(*f).body_type()), 3);
    EXPECT_EQ(*parse_disconnect(*msg(*f).body_as_Disconnect()),
              "protocol version " + std::to_string(version) + " is not supported: this server speaks version 2 "
              "(protocol/PROTOCOL.md); update the client");
    EXPECT_TRUE(p.closed_by_server());
  }
}

TEST_F(ServerTest, WrongAuthTokenIsRejected) {
  ServerOptions o;
  o.ops.auth_token = "open sesame";
  start(o);
  RawPeer p(server_->port());
  ASSERT_TRUE(p.send(build_hello(HelloMsg{kProtocolVersion, "t", "guess", {}})));
  auto f = p.next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(*parse_disconnect(*msg(*f).body_as_Disconnect()), "authentication failed");
}

// The same player joining twice: the newer session wins, the older one is
// told why and closed (as Minecraft does); another player is untouched.
TEST_F(ServerTest, TheSamePlayerJoiningAgainEndsTheOlderSession) {
  start();
  auto older = join("alice");
  auto bob = join("bob");
  auto newer = join("alice");
  auto f = older->next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(*parse_disconnect(*msg(*f).body_as_Disconnect()),
            "logged in from another location: the same player joined again");
  EXPECT_TRUE(testing_support::eventually([&] { return server_->metrics_text().find(
      "terrane_disconnects_total{reason=\"replaced\"} 1") != std::string::npos; }));
  // The newer session and bob still work: each is streamed a chunk.
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  for (RawPeer* p : {newer.get(), bob.get()}) EXPECT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
}

TEST_F(ServerTest, MessageBeforeHelloIsAProtocolError) {
  start();
  RawPeer p(server_->port());
  ASSERT_TRUE(p.send(build_ping(1)));
  auto f = p.next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_NE(parse_disconnect(*msg(*f).body_as_Disconnect())->find("expected Hello"), std::string::npos);
}

TEST_F(ServerTest, ASecondHelloOrAServersMessageAfterTheWelcomeIsAProtocolError) {
  start();
  for (Frame f : {build_hello(HelloMsg{kProtocolVersion, "again", "", {}}), build_edit_ack(1, 2),
                  build_server_notice(ServerNoticeMsg{}), build_admin_result(AdminResultMsg{})}) {
    auto p = join("twice");
    ASSERT_TRUE(p->send(f));
    auto d = p->next_of(wire::Body::Disconnect);
    ASSERT_TRUE(d.has_value());
    EXPECT_EQ(*parse_disconnect(*msg(*d).body_as_Disconnect()), "protocol error: message not accepted from a client");
    EXPECT_TRUE(p->closed_by_server());
  }
}

TEST_F(ServerTest, SilentPeerIsDroppedAtTheHandshakeDeadline) {
  ServerOptions o;
  o.net.session.handshake_timeout = 200ms;
  start(o);
  RawPeer p(server_->port());
  auto f = p.next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(*parse_disconnect(*msg(*f).body_as_Disconnect()), "handshake timeout");
}

TEST_F(ServerTest, TruncatedAndOversizedFramesAffectOnlyTheirSender) {
  start();
  auto good = join("good");
  {
    RawPeer truncated(server_->port());
    const Frame hello = build_hello(HelloMsg{kProtocolVersion, "cut", "", {}});
    ASSERT_TRUE(truncated.send(std::span<const std::uint8_t>(hello).first(hello.size() / 2)));
    truncated.close();  // the server sees EOF mid-frame
  }
  auto big = join("big");
  const std::uint8_t header[4] = {0x01, 0x00, 0x20, 0x00};  // 2 MiB
  ASSERT_TRUE(big->send(header));
  EXPECT_TRUE(big->closed_by_server());
  ASSERT_TRUE(good->send(build_ping(42)));
  auto pong = good->next_of(wire::Body::Pong);
  ASSERT_TRUE(pong.has_value());
  EXPECT_EQ(msg(*pong).body_as_Pong()->nonce(), 42u);
}

TEST_F(ServerTest, InvalidEditIsRejectedNotFatal) {
  start();
  auto p = join("editor");
  EditRequestMsg e;
  e.edit_id = 5;
  e.kind = EditKind::kFillBox;
  e.box = {{0, 0, 0}, {100, 100, 100}};  // over the volume limit
  e.material = materials::kRock;
  ASSERT_TRUE(p->send(build_edit_request(e)));
  auto r = p->next_of(wire::Body::EditReject);
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(msg(*r).body_as_EditReject()->edit_id(), 5u);
  ASSERT_TRUE(p->send(build_ping(1)));
  EXPECT_TRUE(p->next_of(wire::Body::Pong).has_value());
}

TEST_F(ServerTest, EditIsAppliedPersistedAndAcknowledged) {
  start();
  auto p = join("editor");
  const EditRequestMsg e = testing_support::fill_box_edit(77, Region{{1000, 10, 1000}, {1004, 14, 1004}}, materials::kBrick, 128);
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, chunk_of(e.box.min)));
  ASSERT_TRUE(p->send(build_edit_request(e)));
  auto ack = p->next_of(wire::Body::EditAck);
  ASSERT_TRUE(ack.has_value());
  EXPECT_EQ(msg(*ack).body_as_EditAck()->edit_id(), 77u);
  const Vec3i cp = chunk_of(e.box.min);
  std::uint64_t rev = 0;
  Voxel v{};
  server_->inspect([&](const WorldView& c) {
    rev = c.revision(cp);
    v = c.get(e.box.min + Vec3i{1, 1, 1});
  });
  EXPECT_EQ(rev, 1u);
  EXPECT_EQ(v, make_voxel(materials::kBrick, 128));
  p.reset();
  server_->stop();
  auto world = World::open(dir_.string());
  ASSERT_TRUE(world.ok());
  auto stored = (*world)->load_chunk(cp);
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->revision, 1u);
  EXPECT_EQ(stored->chunk.get(local_of(e.box.min)), make_voxel(materials::kBrick, 128));
}

TEST_F(ServerTest, EditOutsideTheFullResolutionRegionIsRejectedWithTheTrueState) {
  start();
  auto p = join("editor");
  // Outside its 24-voxel full-resolution radius, but inside its view, held
  // as mip 1 (so the chunk is loaded and its state can be shown).
  const EditRequestMsg e = testing_support::fill_box_edit(9, Region{{1060, 8, 1002}, {1063, 11, 1005}}, materials::kBrick, 255);
  ASSERT_TRUE(hold_at(*p, {1002.0f, 12.0f, 1002.0f}, {{chunk_of(Vec3i{1002, 12, 1002}), 0}, {chunk_of(e.box.min), 1}}));
  ASSERT_TRUE(p->send(build_edit_request(e)));
  auto f = p->next_of(wire::Body::EditReject);
  ASSERT_TRUE(f.has_value());
  auto r = parse_edit_reject(*msg(*f).body_as_EditReject());
  ASSERT_TRUE(r.ok()) << r.error().describe();
  EXPECT_EQ(r->edit_id, 9u);
  EXPECT_NE(r->reason.find("full-resolution"), std::string::npos) << r->reason;
  ASSERT_EQ(r->box, e.box);
  ASSERT_EQ(r->voxels.size(), 27u);
  server_->inspect([&](const WorldView& c) {
    std::size_t i = 0;
    for (int y = e.box.min.y; y < e.box.max.y; ++y)
      for (int z = e.box.min.z; z < e.box.max.z; ++z)
        for (int x = e.box.min.x; x < e.box.max.x; ++x) EXPECT_EQ(r->voxels[i++], c.get({x, y, z}));
  });
  EXPECT_EQ(server_->counters().edits_applied.load(), 0u);
}

TEST_F(ServerTest, ReadBoxReturnsTheServersVoxelsOnlyForHeldChunks) {
  start();
  auto p = join("reader");
  const Vec3i at{1000, 5, 1000};
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, chunk_of(at)));
  const Region box{at, at + Vec3i{7, 9, 5}};
  ASSERT_TRUE(p->send(build_read_box(3, box)));
  auto f = p->next_of(wire::Body::ReadBoxResult);
  ASSERT_TRUE(f.has_value());
  auto r = parse_read_box_result(*msg(*f).body_as_ReadBoxResult());
  ASSERT_TRUE(r.ok()) << r.error().describe();
  EXPECT_EQ(r->request_id, 3u);
  EXPECT_TRUE(r->error.empty());
  ASSERT_EQ(r->voxels.size(), static_cast<std::size_t>(box.volume()));
  std::size_t solid_count = 0;
  server_->inspect([&](const WorldView& c) {
    std::size_t i = 0;
    for (int y = box.min.y; y < box.max.y; ++y)
      for (int z = box.min.z; z < box.max.z; ++z)
        for (int x = box.min.x; x < box.max.x; ++x) {
          EXPECT_EQ(r->voxels[i], c.get({x, y, z}));
          solid_count += r->voxels[i++].material != kAir;
        }
  });
  EXPECT_GT(solid_count, 0u);  // y 5..14 near the surface of the default world
  // Far away: nothing is loaded for it, and nothing gets loaded.
  const Region far{{500000, 0, 500000}, {500004, 4, 500004}};
  ASSERT_TRUE(p->send(build_read_box(4, far)));
  f = p->next_of(wire::Body::ReadBoxResult);
  ASSERT_TRUE(f.has_value());
  r = parse_read_box_result(*msg(*f).body_as_ReadBoxResult());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->request_id, 4u);
  EXPECT_FALSE(r->error.empty());
  bool loaded = true;
  server_->inspect([&](const WorldView& c) { loaded = c.loaded(chunk_of(far.min)); });
  EXPECT_FALSE(loaded);
}

TEST_F(ServerTest, PresenceListsOtherClientsInView) {
  ServerOptions o;
  o.world.presence_hz = 10;
  start(o);
  auto a = join("a");
  auto b = join("b");
  ASSERT_TRUE(a->send(build_client_state(ClientStateMsg{{10.5f, 40.0f, 10.5f}, 64, 32})));
  ASSERT_TRUE(b->send(build_client_state(ClientStateMsg{{20.5f, 41.0f, 12.5f}, 64, 32})));
  // a sees b where b said it is (and never itself).
  for (int tries = 0; tries < 200; ++tries) {
    auto f = a->next_of(wire::Body::Presence);
    ASSERT_TRUE(f.has_value());
    auto entries = parse_presence(*msg(*f).body_as_Presence());
    ASSERT_TRUE(entries.ok());
    if (entries->empty()) continue;
    ASSERT_EQ(entries->size(), 1u);
    EXPECT_EQ((*entries)[0].position, (Vec3f{20.5f, 41.0f, 12.5f}));
    return;
  }
  FAIL() << "no presence entry arrived";
}

TEST_F(ServerTest, ChunkHashesArePushedForFullResolutionChunks) {
  ServerOptions o;
  o.replication.hash_push_ms = 100;
  start(o);
  auto p = join("verifier");
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  auto f = p->next_of(wire::Body::ChunkHash);
  ASSERT_TRUE(f.has_value());
  auto h = parse_chunk_hash(*msg(*f).body_as_ChunkHash());
  ASSERT_TRUE(h.ok());
  std::uint64_t expected = 0;
  server_->inspect([&](const WorldView& c) {
    expected = chunk_hash(c.chunk(h->chunk_pos), c.revision(h->chunk_pos));
  });
  EXPECT_EQ(h->hash, expected);
}

TEST_F(ServerTest, ChunksNobodyHoldsAreUnloadedAndComeBackWithTheirEdits) {
  ServerOptions o;
  o.world.resident_chunks = 0;  // unload everything nobody holds, once a second
  o.replication.max_speed = 0;  // the walker teleports
  start(o);
  auto p = join("walker");
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  const EditRequestMsg e = testing_support::fill_box_edit(1, Region{{1000, 10, 1000}, {1002, 12, 1002}}, materials::kBrick, 255);
  ASSERT_TRUE(p->send(build_edit_request(e)));
  ASSERT_TRUE(p->next_of(wire::Body::EditAck).has_value());
  // Walk far away: the old chunks are released, then unloaded.
  ASSERT_TRUE(hold_full(*p, {9002.0f, 12.0f, 9002.0f}, chunk_of(Vec3i{9002, 12, 9002})));
  ASSERT_TRUE(testing_support::eventually([&] {
    bool unloaded = false;
    server_->inspect([&](const WorldView& c) { unloaded = !c.loaded(cp); });
    return unloaded;
  }));
  EXPECT_GT(server_->counters().chunks_unloaded.load(), 0u);
  // Back again: the chunk is reloaded from the store with its edit.
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  server_->inspect([&](const WorldView& c) {
    ASSERT_TRUE(c.loaded(cp));
    EXPECT_EQ(c.revision(cp), 1u);
    EXPECT_EQ(c.get({1001, 11, 1001}), solid(materials::kBrick));
  });
}

using HeldMap = std::map<Vec3i, HeldChunkMsg, bool (*)(Vec3i, Vec3i)>;

HeldMap empty_held() {
  return HeldMap([](Vec3i a, Vec3i b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); });
}

// Reads stream batches into held (chunk -> what the client holds), counting
// records, until done(held) or a frame of type stop arrives; false when the
// stream ends first (the peer's deadline per frame is generous).
bool read_stream(RawPeer& p, HeldMap& held, std::size_t* records, const std::function<bool(const HeldMap&)>& done,
                 wire::Body stop = wire::Body::NONE) {
  StreamDecodeScratch scratch;
  while (!done(held)) {
    auto f = p.next();
    if (!f) return false;
    const wire::Message& m = msg(*f);
    if (stop != wire::Body::NONE && m.body_type() == stop) return true;
    if (m.body_type() != wire::Body::StreamBatch) continue;
    auto r = parse_stream_batch(*m.body_as_StreamBatch());
    if (!r) return false;
    const Status st = decode_stream_batch(*r, scratch, [&](const StreamRecord& rec) -> Status {
      // A horizon image is no holding (never claimed): each chunk's own record follows.
      if (rec.kind == StreamRecordKind::kHorizon) return Ok{};
      ++*records;
      if (rec.kind == StreamRecordKind::kReleased)
        held.erase(rec.chunk_pos);
      else
        held[rec.chunk_pos] =
            HeldChunkMsg{rec.chunk_pos, Holding{rec.form(), rec.revision}};
      return Ok{};
    });
    if (!st) return false;
  }
  return true;
}

// True when every chunk of the view is held at the level the view rule
// (common/world/view.h) promises: Empty or full resolution inside the radius, the
// desired mip (or Empty) beyond it.
bool view_complete(const HeldMap& held, const ClientStateMsg& where,
                   const WorldBounds& b = default_world_meta().bounds) {
  for (const Vec3i cp : chunks_in_view(where.position, where.view_distance, b)) {
    auto it = held.find(cp);
    if (it == held.end()) return false;
    const Holding& h = it->second.holding;
    if (h.form != HoldingForm::kEmpty && h.level() != desired_level(where.position, cp, where.full_res_radius))
      return false;
  }
  return true;
}

// What a client holds once its view at where is complete (what it claims
// in Holdings when it comes back); empty if the stream ends first.
std::vector<HeldChunkMsg> holdings_after_view(RawPeer& p, const ClientStateMsg& where) {
  std::vector<HeldChunkMsg> out;
  HeldMap held = empty_held();
  std::size_t records = 0;
  if (!p.send(build_client_state(where)) ||
      !read_stream(p, held, &records, [&](const HeldMap& h) { return view_complete(h, where); }))
    return out;
  for (const auto& [cp, h] : held)
    if (claimable(h.holding.form)) out.push_back(h);  // as a client claims: no estimates
  return out;
}

TEST_F(ServerTest, ADistantViewIsServedFromCoarseImagesWithoutReadingItsChunks) {
  // A stored world around (1000, y, 1000), as terrane-world generate leaves
  // it: every chunk that is not Air has a row (and a coarse entry).
  std::map<std::tuple<int, int, int>, CoarseVoxels> stored;
  {
    auto world = World::create(dir_.string(), default_world_meta());
    ASSERT_TRUE(world.ok()) << world.error().message;
    std::vector<ChunkWrite> writes;
    for (int cx = 21; cx <= 41; ++cx)
      for (int cz = 21; cz <= 41; ++cz)
        for (int cy = -4; cy < 8; ++cy) {
          const Vec3i cp{cx, cy, cz};
          const Chunk c = (*world)->generate_chunk(cp);
          if (c.empty()) continue;
          writes.push_back(ChunkWrite{cp, 3, encode_chunk_blob(c), coarse_voxels(&c)});
          stored[{cp.x, cp.y, cp.z}] = coarse_voxels(&c);
        }
    ASSERT_TRUE((*world)->store().save_chunks(writes).ok());
  }
  // Exact mips only (estimates for the chunks never stored are tested
  // below): the unstored chunks are judged Air or generated when wanted.
  ServerOptions o;
  o.replication.horizon_estimates = false;
  start(o);
  auto p = join("far-sighted");
  const ClientStateMsg where{{1000.5f, 60.0f, 1000.5f}, 300, 32};
  ASSERT_TRUE(p->send(build_client_state(where)));
  // Read until every chunk of the view is held at its level, keeping the
  // coarsest mips received.
  HeldMap held = empty_held();
  std::map<std::tuple<int, int, int>, std::pair<std::uint64_t, CoarseVoxels>> coarse;
  StreamDecodeScratch scratch;
  while (!view_complete(held, where)) {
    auto f = p->next_of(wire::Body::StreamBatch);
    ASSERT_TRUE(f.has_value()) << "the stream ended before the view was complete";
    auto r = parse_stream_batch(*msg(*f).body_as_StreamBatch());
    ASSERT_TRUE(r.ok());
    ASSERT_TRUE(decode_stream_batch(*r, scratch, [&](const StreamRecord& rec) -> Status {
                  if (rec.kind == StreamRecordKind::kReleased) {
                    held.erase(rec.chunk_pos);
                    return Ok{};
                  }
                  held[rec.chunk_pos] = HeldChunkMsg{rec.chunk_pos, Holding{rec.form(), rec.revision}};
                  if (rec.kind == StreamRecordKind::kMip3) {
                    CoarseVoxels v{};
                    std::copy_n(rec.voxels->voxels().begin(), kCoarseVoxels, v.begin());
                    coarse[{rec.chunk_pos.x, rec.chunk_pos.y, rec.chunk_pos.z}] = {rec.revision, v};
                  }
                  return Ok{};
                }).ok());
  }
  // Every coarsest mip sent is the stored chunk's, at its revision.
  ASSERT_GT(coarse.size(), 100u);
  for (const auto& [key, got] : coarse) {
    auto it = stored.find(key);
    ASSERT_NE(it, stored.end()) << "a mip for a chunk that was never stored";
    EXPECT_EQ(got.first, 3u);
    EXPECT_EQ(got.second, it->second);
  }
  // Chunks were read only for finer levels: the coarsest came from images.
  std::size_t finer = 0;
  for (const Vec3i cp : chunks_in_view(where.position, where.view_distance, default_world_meta().bounds))
    finer += desired_level(where.position, cp, where.full_res_radius) < kMipLevels - 1;
  const StorageCounters& st = server_->storage_counters();
  EXPECT_GT(st.coarse_images_read.load(), 0u);
  EXPECT_LE(st.loaded_from_store.load() + st.generated.load(), finer)
      << "loaded " << st.loaded_from_store.load() << ", generated " << st.generated.load();
  server_->inspect([&](const WorldView& w) { EXPECT_LE(w.loaded_count(), finer); });
}

TEST_F(ServerTest, ReplacedEstimatesAreUnloadedOnceNobodyWatchesThem) {
  // Nothing kept beyond what clients hold, on a world never generated.
  ServerOptions o;
  o.world.resident_chunks = 0;
  o.replication.max_speed = 0;
  start(o);
  auto p = join("explorer");
  const Vec3f here{1000.5f, 60.0f, 1000.5f};
  ASSERT_TRUE(p->send(build_client_state(ClientStateMsg{here, 192, 32})));
  // The view's coarse forms come as estimates; the server generates those
  // chunks in the background until none is left (the stream is read
  // meanwhile, so the client keeps up).
  std::size_t waiting = 0;
  ASSERT_TRUE(testing_support::eventually([&] {
    while (p->next(0)) {
    }
    server_->inspect([&](const WorldView& w) { waiting = w.estimates_waiting(); });
    return server_->counters().estimates_sent.load() > 0 && waiting == 0;
  })) << waiting << " estimates still waiting";
  EXPECT_GT(server_->counters().estimates_replaced.load(), 0u);
  // Far away with a small view, the client watches nothing of the old view:
  // what was generated there, sky and terrain, goes from memory.
  const Vec3f far{here.x + 4000.0f, here.y, here.z};
  ASSERT_TRUE(p->send(build_client_state(ClientStateMsg{far, 32, 32})));
  const std::size_t near = chunks_in_view(far, 32, default_world_meta().bounds).size();
  std::size_t loaded = 0;
  EXPECT_TRUE(testing_support::eventually([&] {
    while (p->next(0)) {
    }
    server_->inspect([&](const WorldView& w) { loaded = w.loaded_count(); });
    return loaded <= near;
  })) << loaded << " chunks still loaded, " << near << " in view";
}

TEST_F(ServerTest, AWorldBorderBoundsStreamingAndEditsReachesClientsAndIsKept) {
  ServerOptions o;
  o.border_set = true;
  o.border = WorldBounds{0, 1, true, 0, 96, -64, 32};  // x in [0, 96), z in [-64, 32)
  start(o);
  RawPeer p(server_->port());
  const WelcomeMsg w = welcome_of(p, "edge");
  ASSERT_TRUE(w.bounded_xz);
  EXPECT_EQ(w.bounds_min_x, 0);
  EXPECT_EQ(w.bounds_max_x, 96);
  EXPECT_EQ(w.bounds_min_z, -64);
  EXPECT_EQ(w.bounds_max_z, 32);
  EXPECT_EQ(w.default_view_distance, 2048);  // the defaults: the view a client gets before it says
  EXPECT_EQ(w.max_view_distance, 2048);
  EXPECT_EQ(w.default_full_res_radius, 128);
  // A client at the border's corner: its view completes with the chunks
  // inside the border, and nothing beyond it is ever sent.
  const ClientStateMsg where{{8.5f, w.spawn.y, 8.5f}, 128, 48};
  ASSERT_TRUE(p.send(build_client_state(where)));
  HeldMap held = empty_held();
  std::size_t records = 0;
  ASSERT_TRUE(read_stream(p, held, &records, [&](const HeldMap& h) { return view_complete(h, where, w.bounds()); }));
  for (const auto& [cp, h] : held) EXPECT_TRUE(w.bounds().touches_chunk(cp)) << cp.x << "," << cp.y << "," << cp.z;
  // An edit beyond the border is refused.
  const EditRequestMsg e = testing_support::fill_box_edit(5, Region{{-4, 10, 4}, {-2, 12, 6}}, materials::kBrick, 255);
  ASSERT_TRUE(p.send(build_edit_request(e)));
  auto r = p.next_of(wire::Body::EditReject);
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(parse_edit_reject(*msg(*r).body_as_EditReject())->reason, "edit outside the world");
  p.close();
  // Kept in the world: a restart without --border still has it; 'none' removes it.
  server_->stop();
  server_.reset();
  start();
  RawPeer again(server_->port());
  EXPECT_TRUE(welcome_of(again, "edge").bounded_xz);
  again.close();
  server_->stop();
  server_.reset();
  ServerOptions none;
  none.border_set = true;
  start(none);
  RawPeer open(server_->port());
  EXPECT_FALSE(welcome_of(open, "edge").bounded_xz);
}

// A client standing at the wire's edge (x = +-(2^24 - 1)) is sent nothing
// beyond +-2^19 chunks: each such record is a protocol error at the client
// (decode_stream_batch refuses it). Its view there is clipped, and what is
// left of it arrives whole.
TEST_F(ServerTest, AClientAtTheWiresEdgeIsSentOnlyChunksWithinTheWiresRange) {
  start();
  for (const float x : {16777215.0f, -16777216.0f}) {
    auto p = join("edge");
    const ClientStateMsg where{{x, 20.0f, 0.0f}, 128, 32};
    std::vector<Vec3i> expected;
    for (const Vec3i cp : chunks_in_view(where.position, where.view_distance, default_world_meta().bounds))
      if (wire_chunk_ok(cp)) expected.push_back(cp);
    ASSERT_FALSE(expected.empty());
    HeldMap held = empty_held();
    std::size_t records = 0;
    ASSERT_TRUE(p->send(build_client_state(where)));
    // read_stream fails on a record the client would refuse.
    ASSERT_TRUE(read_stream(*p, held, &records, [&](const HeldMap& h) {
      return std::all_of(expected.begin(), expected.end(), [&](Vec3i cp) { return h.count(cp) != 0; });
    })) << "x " << x << ": " << held.size() << " of " << expected.size() << " chunks before the stream failed";
    for (const auto& [cp, h] : held) EXPECT_TRUE(wire_chunk_ok(cp)) << cp.x << "," << cp.y << "," << cp.z;
  }
}

// Horizon images go out nearest region first (by its nearest chunk in
// view), whatever order the world makes them in.
TEST_F(ServerTest, HorizonImagesArriveNearestRegionFirst) {
  start();
  auto p = join("far-sighted");
  const ClientStateMsg where{{3000.0f, 40.0f, -2000.0f}, 640, 32};
  // The regions in the order of their first chunk in the view rule's order.
  std::vector<Vec3i> order;
  {
    std::set<std::tuple<int, int, int>> seen;
    for (const Vec3i cp : chunks_in_view(where.position, where.view_distance, default_world_meta().bounds)) {
      const Vec3i r = coarse_region_of(cp);
      if (seen.insert({r.x, r.y, r.z}).second) order.push_back(r);
    }
  }
  ASSERT_GT(order.size(), 20u);
  ASSERT_TRUE(p->send(build_client_state(where)));
  std::vector<Vec3i> got;
  StreamDecodeScratch scratch;
  bool own_record = false;  // horizon images come before any chunk's own record
  while (!own_record) {
    auto f = p->next();
    ASSERT_TRUE(f.has_value()) << got.size() << " images, then the stream ended";
    const wire::Message& m = msg(*f);
    if (m.body_type() != wire::Body::StreamBatch) continue;
    auto r = parse_stream_batch(*m.body_as_StreamBatch());
    ASSERT_TRUE(r.ok());
    ASSERT_TRUE(decode_stream_batch(*r, scratch, [&](const StreamRecord& rec) -> Status {
                  if (rec.kind == StreamRecordKind::kHorizon)
                    got.push_back(coarse_region_of(rec.chunk_pos));
                  else
                    own_record = true;
                  return Ok{};
                }).ok());
  }
  ASSERT_EQ(got.size(), order.size());
  for (std::size_t i = 0; i < got.size(); ++i)
    ASSERT_EQ(got[i], order[i]) << "image " << i << " of " << got.size();
}

// A server serves views of at most 4,096 voxels, whatever its options ask:
// a view's table of chunk offsets grows with its cube.
TEST_F(ServerTest, AViewCapBeyondTheLimitIsServedAsTheLimit) {
  ServerOptions o;
  o.replication.max_view_distance = 1 << 20;
  start(o);
  RawPeer p(server_->port());
  const WelcomeMsg w = welcome_of(p, "wide");
  EXPECT_EQ(w.max_view_distance, ReplicationOptions::kViewDistanceLimit);
  EXPECT_EQ(w.max_view_distance, 4096);
  EXPECT_EQ(w.default_view_distance, 2048);
}

// A new view's images by distance: to a client that takes level 6
// (features bit 2), level 4 within a quarter of the view and 256 voxels,
// level 5 within 1,024, level 6 beyond; to one that does not, level 4
// within a quarter of the view and level 5 beyond, as before the bit.
TEST_F(ServerTest, HorizonImagesBeyond1024AreLevel6ForAClientThatTakesThem) {
  ServerOptions o;
  o.replication.max_view_distance = 1280;
  start(o);
  const ClientStateMsg where{{3000.0f, 40.0f, -2000.0f}, 1280, 32};
  // Each region's nearest chunk in view (the view rule's order).
  std::map<std::tuple<int, int, int>, std::int64_t> nearest;  // region -> d^2
  const Vec3i centre = view_chunk(where.position);
  for (const Vec3i cp : chunks_in_view(where.position, where.view_distance, default_world_meta().bounds)) {
    const Vec3i r = coarse_region_of(cp);
    nearest.try_emplace({r.x, r.y, r.z}, offset_dist2(cp - centre));
  }
  for (const std::uint32_t features : {kFeatureOuterHorizon, 0u}) {
    auto p = join(features != 0 ? "outer" : "plain", features);
    ASSERT_TRUE(p->send(build_client_state(where)));
    std::map<int, std::size_t> levels;
    std::size_t images = 0;
    StreamDecodeScratch scratch;
    bool own_record = false;
    while (!own_record) {
      auto f = p->next();
      ASSERT_TRUE(f.has_value()) << images << " images, then the stream ended";
      const wire::Message& m = msg(*f);
      if (m.body_type() != wire::Body::StreamBatch) continue;
      auto r = parse_stream_batch(*m.body_as_StreamBatch());
      ASSERT_TRUE(r.ok());
      ASSERT_TRUE(decode_stream_batch(*r, scratch, [&](const StreamRecord& rec) -> Status {
                    if (rec.kind != StreamRecordKind::kHorizon) {
                      own_record = true;
                      return Ok{};
                    }
                    ++images;
                    ++levels[rec.level];
                    const Vec3i region = coarse_region_of(rec.chunk_pos);
                    const auto it = nearest.find({region.x, region.y, region.z});
                    EXPECT_NE(it, nearest.end()) << "an image of a region out of view";
                    if (it == nearest.end()) return Ok{};
                    const std::int64_t d2 = it->second;
                    // Level 4 within V / 4 (320), or 256 with level 6.
                    const std::int64_t near = features != 0 ? 256 : 320;
                    const int want = d2 <= near * near                        ? kHorizonNearLevel
                                     : d2 <= 1024 * 1024 || features == 0 ? kHorizonFarLevel
                                                                             : kHorizonOuterLevel;
                    EXPECT_EQ(rec.level, want) << "region " << region.x << "," << region.y << "," << region.z;
                    return Ok{};
                  }).ok());
    }
    EXPECT_EQ(images, nearest.size()) << "one image per region in view";
    EXPECT_GT(levels[kHorizonNearLevel], 0u);
    EXPECT_GT(levels[kHorizonFarLevel], 0u);
    if (features != 0)
      EXPECT_GT(levels[kHorizonOuterLevel], 0u);
    else
      EXPECT_EQ(levels.count(kHorizonOuterLevel), 0u) << "level 6 only to a client that takes it";
  }
}

// The format versions of a run of count units of n^3 at the start of bytes
// (versions[v] counts units of version v); false if one does not decode.
bool count_unit_versions(int n, std::size_t count, std::span<const std::uint8_t> bytes, std::map<int, int>& versions) {
  std::vector<Voxel> voxels(static_cast<std::size_t>(n) * n * n);
  for (std::size_t i = 0; i < count; ++i) {
    auto used = net_codec_decode_prefix(n, bytes, voxels);
    if (!used) return false;
    ++versions[bytes[0] & 0x0F];
    bytes = bytes.subspan(*used);
  }
  return bytes.empty();
}

// The same for an update batch's units (NET_CODEC.md, "Update batches").
bool count_update_versions(std::span<const std::uint8_t> data, std::map<int, int>& versions) {
  std::size_t pos = 1;  // the batch's version byte
  const auto varint = [&](std::uint64_t& v) { return get_varint(data, pos, 10, v) == VarintRead::kOk; };
  std::uint64_t count = 0;
  if (data.empty() || !varint(count)) return false;
  std::vector<Voxel> voxels(64);
  for (std::uint64_t i = 0; i < count; ++i) {
    std::uint64_t tag = 0, d = 0;
    if (!varint(tag)) return false;
    if ((tag & 1) == 0 && !(varint(d) && varint(d) && varint(d))) return false;
    auto used = net_codec_decode_prefix(4, data.subspan(pos), voxels);
    if (!used) return false;
    ++versions[data[pos] & 0x0F];
    pos += *used;
  }
  return pos == data.size();
}

// Network codec version 2 (features bit 3): a client that sets the bit gets
// the server's units in version 2 where that is shorter (the generated
// world's smooth surfaces); one that does not gets every unit in version 1,
// stream records and update batches alike, with the same voxels.
TEST_F(ServerTest, UnitsAreVersion2OnlyForAClientThatTakesThem) {
  start();
  std::map<std::tuple<int, int, int>, std::pair<std::uint64_t, Box>> first_full;  // chunk -> revision, voxels
  for (const std::uint32_t features : {kFeatureCodec2, 0u}) {
    RawPeer p(server_->port());
    const WelcomeMsg w = welcome_of(p, features != 0 ? "two" : "one", features);
    const ClientStateMsg where{w.spawn, 96, 64};
    ASSERT_TRUE(p.send(build_client_state(where)));
    std::map<int, int> stream_versions;
    std::size_t fulls = 0, compared = 0;
    while (fulls < 40) {
      auto f = p.next_of(wire::Body::StreamBatch);
      ASSERT_TRUE(f.has_value()) << fulls << " Full records, then the stream ended";
      ASSERT_TRUE(for_each_record(msg(*f), [&](const StreamRecord& rec) {
        if (!gives_form(rec.kind) || rec.payload.empty()) return;
        const bool full = rec.kind == StreamRecordKind::kFull;
        EXPECT_TRUE(count_unit_versions(full ? 16 : kChunkSize >> rec.level, full ? 8 : 1, rec.payload, stream_versions));
        if (!full) return;
        ++fulls;
        // Both clients' Full records of a chunk at one revision hold the
        // same voxels.
        const auto key = std::make_tuple(rec.chunk_pos.x, rec.chunk_pos.y, rec.chunk_pos.z);
        auto [it, fresh] = first_full.try_emplace(key, rec.revision, *rec.voxels);
        if (!fresh && it->second.first == rec.revision) {
          EXPECT_EQ(it->second.second, *rec.voxels);
          ++compared;
        }
      }));
    }
    // An edit where the client stands: its UpdateBatch's units.
    const Vec3i at{static_cast<int>(std::floor(w.spawn.x)), static_cast<int>(std::floor(w.spawn.y)),
                   static_cast<int>(std::floor(w.spawn.z))};
    const EditRequestMsg e = testing_support::fill_box_edit(features + 1, Region{at - Vec3i{3, 3, 3}, at + Vec3i{3, 3, 3}},
                                                            features != 0 ? materials::kBrick : materials::kSlate, 100);
    ASSERT_TRUE(p.send(build_edit_request(e)));
    auto both = p.next_of_both(wire::Body::EditAck, wire::Body::UpdateBatch);
    ASSERT_TRUE(both.has_value());
    auto batch = parse_update_batch(*msg(both->second).body_as_UpdateBatch());
    ASSERT_TRUE(batch.ok());
    std::map<int, int> update_versions;
    EXPECT_TRUE(count_update_versions(batch->data, update_versions));
    const auto of = [](const std::map<int, int>& m, int version) { return m.count(version) ? m.at(version) : 0; };
    EXPECT_GT(of(update_versions, 1) + of(update_versions, 2), 0);
    if (features != 0) {
      EXPECT_GT(of(stream_versions, 2), 0) << "no unit of the generated terrain in version 2";
    } else {
      EXPECT_EQ(of(stream_versions, 2), 0) << "version-2 units to a version-1 client";
      EXPECT_EQ(of(update_versions, 2), 0);
      EXPECT_GT(compared, 10u) << "chunks both clients got at the same revision";
    }
    p.close();
  }
}

TEST_F(ServerTest, AResumingClientIsNotSentWhatItStillHolds) {
  start();
  const ClientStateMsg where{{1002.0f, 12.0f, 1002.0f}, 96, 24};
  std::vector<HeldChunkMsg> claims = holdings_after_view(*join("a"), where);
  ASSERT_GT(claims.size(), 50u);
  // Meanwhile another client changes the home chunk: that one is stale.
  auto c = join("c");
  const Vec3i home = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*c, where.position, home));
  const EditRequestMsg e = testing_support::fill_box_edit(1, Region{{1001, 11, 1001}, {1003, 13, 1003}}, materials::kBrick, 255);
  ASSERT_TRUE(c->send(build_edit_request(e)));
  ASSERT_TRUE(c->next_of(wire::Body::EditAck).has_value());

  auto b = join("b");
  ASSERT_TRUE(b->send(build_holdings(claims)));
  ASSERT_TRUE(b->send(build_client_state(where)));
  HeldMap held = empty_held();
  std::size_t records = 0;
  // The stale home chunk comes again at full resolution ...
  ASSERT_TRUE(read_stream(*b, held, &records, [&](const HeldMap& h) {
    auto it = h.find(home);
    return it != h.end() && it->second.holding == Holding{HoldingForm::kFull, 1};
  }));
  // ... and every other claim is adopted: the server answers a hash request
  // for a claimed chunk only once it has adopted or resent it, so when every
  // claim's hash has come, every claim was dealt with (and counted). (A
  // pushed hash names a chunk already held, so chunks are counted once.)
  for (const HeldChunkMsg& h : claims) ASSERT_TRUE(b->send(build_chunk_hash_request(h.chunk_pos)));
  HeldMap hashed = empty_held();
  {
    StreamDecodeScratch scratch;
    while (hashed.size() < claims.size()) {
      auto f = b->next();
      ASSERT_TRUE(f.has_value()) << hashed.size() << " of " << claims.size() << " hashes answered";
      const wire::Message& m = msg(*f);
      if (m.body_type() == wire::Body::ChunkHash) {
        auto h = parse_chunk_hash(*m.body_as_ChunkHash());
        ASSERT_TRUE(h.ok());
        hashed[h->chunk_pos] = HeldChunkMsg{h->chunk_pos, Holding{HoldingForm::kFull, h->revision}};
      }
      if (m.body_type() != wire::Body::StreamBatch) continue;
      auto r = parse_stream_batch(*m.body_as_StreamBatch());
      ASSERT_TRUE(r.ok());
      ASSERT_TRUE(decode_stream_batch(*r, scratch, [&](const StreamRecord& rec) -> Status {
                    ++records;
                    held[rec.chunk_pos] = HeldChunkMsg{rec.chunk_pos, Holding{rec.form(), rec.revision}};
                    return Ok{};
                  }).ok());
    }
  }
  EXPECT_EQ(server_->counters().chunks_resumed.load(), claims.size() - 1);
  // ... so by a read answered on the data queue, after everything streamed
  // before it, nothing else came: the home chunk's coarse mip, then full.
  ASSERT_TRUE(b->send(build_read_box(7, Region{{1000, 10, 1000}, {1001, 11, 1001}})));
  ASSERT_TRUE(read_stream(*b, held, &records, [](const HeldMap&) { return false; }, wire::Body::ReadBoxResult));
  EXPECT_LE(records, 3u);
  ASSERT_EQ(held.count(home), 1u);
  EXPECT_EQ(held.at(home).holding, (Holding{HoldingForm::kFull, 1}));
}

// The edits a client queued while away come right after its Holdings and
// ClientState, before its claims are settled: taken where it claims full
// resolution within its radius, refused where it claims a mip.
TEST_F(ServerTest, AResumingClientsEditsAreTakenWhereItClaimsFullResolution) {
  start();
  const ClientStateMsg where{{1002.0f, 12.0f, 1002.0f}, 96, 24};
  const Vec3i home = chunk_of(Vec3i{1002, 12, 1002}), east = home + Vec3i{1, 0, 0};
  std::vector<HeldChunkMsg> claims = holdings_after_view(*join("a"), where);
  bool home_full = false, east_full = false;
  for (HeldChunkMsg& h : claims) {
    if (h.chunk_pos == home) home_full = h.holding.form == HoldingForm::kFull;
    if (h.chunk_pos == east) {
      east_full = h.holding.form == HoldingForm::kFull;
      h.holding.form = HoldingForm::kMip2;  // claimed as a mip
    }
  }
  ASSERT_TRUE(home_full && east_full);
  auto b = join("b");
  // One write, so the server reads the four frames together and checks the
  // edits before any claim is settled (sent apart, a slow run could refine
  // the chunk claimed as a mip to full resolution first, and take edit 2).
  Frame burst;
  for (const Frame& f :
       {build_holdings(claims), build_client_state(where),
        build_edit_request(
            testing_support::fill_box_edit(1, Region{{1001, 11, 1001}, {1003, 13, 1003}}, materials::kBrick, 255)),
        build_edit_request(
            testing_support::fill_box_edit(2, Region{{1025, 11, 1001}, {1027, 13, 1003}}, materials::kBrick, 255))})
    burst.insert(burst.end(), f.begin(), f.end());
  ASSERT_LT(burst.size(), 64u * 1024) << "more than the server reads at once";
  ASSERT_TRUE(b->send(burst));
  std::optional<std::string> rejected;
  bool acked = false;
  while (!acked || !rejected) {
    auto f = b->next();
    ASSERT_TRUE(f.has_value()) << "both edits answered";
    const wire::Message& m = msg(*f);
    if (m.body_type() == wire::Body::EditAck) {
      EXPECT_EQ(m.body_as_EditAck()->edit_id(), 1u);
      acked = true;
    } else if (m.body_type() == wire::Body::EditReject) {
      auto r = parse_edit_reject(*m.body_as_EditReject());
      ASSERT_TRUE(r.ok());
      EXPECT_EQ(r->edit_id, 2u) << r->reason;
      rejected = r->reason;
    }
  }
  EXPECT_EQ(*rejected, "edit outside the full-resolution region");
}

// --- durability ----------------------------------------------------------------

// Moves the peer to pos and reads the stream until every chunk of want has
// arrived at full resolution (Full or Empty); returns their revisions, or
// fewer entries if the stream ends first.
std::map<std::tuple<int, int, int>, std::uint64_t> full_revisions(RawPeer& p, Vec3f pos, const std::vector<Vec3i>& want) {
  std::map<std::tuple<int, int, int>, std::uint64_t> got;
  if (!p.send(build_client_state(ClientStateMsg{pos, 96, 24}))) return got;
  StreamDecodeScratch scratch;
  while (got.size() < want.size()) {
    auto f = p.next_of(wire::Body::StreamBatch);
    if (!f) break;
    auto records = parse_stream_batch(*msg(*f).body_as_StreamBatch());
    if (!records) break;
    const auto st = decode_stream_batch(*records, scratch, [&](const StreamRecord& r) -> Status {
      const bool full = r.kind == StreamRecordKind::kFull || r.kind == StreamRecordKind::kEmpty;
      if (full && std::find(want.begin(), want.end(), r.chunk_pos) != want.end())
        got[{r.chunk_pos.x, r.chunk_pos.y, r.chunk_pos.z}] = r.revision;
      return Ok{};
    });
    if (!st) break;
  }
  return got;
}

std::tuple<int, int, int> key(Vec3i v) { return {v.x, v.y, v.z}; }

// Runs one SQL statement on the world's database behind the store's back.
void run_sql(const fs::path& world_dir, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((world_dir / kWorldDatabaseName).string().c_str(), &db), SQLITE_OK);
  char* err = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &err);
  EXPECT_EQ(rc, SQLITE_OK) << sql << ": " << (err ? err : "?");
  sqlite3_free(err);
  sqlite3_close(db);
}

TEST_F(ServerTest, DamagedChunkIsQuarantinedLoggedAndTheRestStillServed) {
  const Vec3i bad_cp = chunk_of(Vec3i{1002, 12, 1002});
  const Vec3i good_cp = bad_cp + Vec3i{0, 0, -1};
  Chunk generated_bad;
  {
    auto world = World::create(dir_.string(), default_world_meta());
    ASSERT_TRUE(world.ok()) << world.error().message;
    generated_bad = (*world)->generate_chunk(bad_cp);
    std::vector<ChunkWrite> writes;
    for (const Vec3i cp : {bad_cp, good_cp}) {
      // Stored content differs from the generator's: a brick corner.
      Chunk c = (*world)->generate_chunk(cp);
      c.modify(Region{{0, 0, 0}, {2, 2, 2}}, [](Vec3i, Voxel) { return solid(materials::kBrick); });
      writes.push_back(ChunkWrite{cp, 5, encode_chunk_blob(c), coarse_voxels(&c)});
    }
    ASSERT_TRUE((*world)->store().save_chunks(writes).ok());
  }
  // Damage one blob as a disk fault would: cut it in half.
  const std::string where = " WHERE cx = " + std::to_string(bad_cp.x) + " AND cy = " + std::to_string(bad_cp.y) +
                            " AND cz = " + std::to_string(bad_cp.z);
  run_sql(dir_, "UPDATE chunks SET data = substr(data, 1, length(data) / 2)" + where);
  std::vector<std::uint8_t> bad_blob;
  {
    auto store = SqliteStore::open(dir_.string());
    ASSERT_TRUE(store.ok());
    ASSERT_TRUE((*store)
                    ->for_each_chunk([&](Vec3i cp, std::uint64_t, std::span<const std::uint8_t> blob) {
                      if (cp == bad_cp) bad_blob.assign(blob.begin(), blob.end());
                    })
                    .ok());
    ASSERT_FALSE(bad_blob.empty());
    ASSERT_FALSE(decode_chunk_blob(bad_blob).ok());
  }

  std::ostringstream log;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  server_log().sinks().push_back(sink);
  start();
  auto p = join("viewer");
  const auto revs = full_revisions(*p, {1002.0f, 12.0f, 1002.0f}, {bad_cp, good_cp});
  ASSERT_EQ(revs.size(), 2u) << "both chunks are served";
  EXPECT_EQ(revs.at(key(good_cp)), 5u);
  EXPECT_EQ(revs.at(key(bad_cp)), 6u) << "generated, above the quarantined revision";
  server_->inspect([&](const WorldView& c) {
    EXPECT_EQ(c.get(chunk_origin(good_cp)), solid(materials::kBrick));
    EXPECT_EQ(c.get(chunk_origin(bad_cp)), generated_bad.get({0, 0, 0}));
  });
  EXPECT_EQ(server_->storage_counters().quarantined.load(), 1u);
  // Editing the quarantined chunk writes a fresh row; the damaged one stays aside.
  const EditRequestMsg e = testing_support::fill_box_edit(3, Region{{1000, 10, 1000}, {1002, 12, 1002}}, materials::kSnow, 200);
  ASSERT_TRUE(p->send(build_edit_request(e)));
  ASSERT_TRUE(p->next_of(wire::Body::EditAck).has_value());
  p.reset();
  server_->stop();
  server_.reset();
  std::erase(server_log().sinks(), sink);

  const std::string logged = log.str();
  const std::string coords = "chunk (" + std::to_string(bad_cp.x) + "," + std::to_string(bad_cp.y) + "," +
                             std::to_string(bad_cp.z) + ")";
  EXPECT_NE(logged.find(coords), std::string::npos) << logged;
  EXPECT_NE(logged.find("quarantine"), std::string::npos) << logged;
  EXPECT_NE(logged.find("[error]"), std::string::npos) << logged;

  auto store = SqliteStore::open(dir_.string());
  ASSERT_TRUE(store.ok());
  std::vector<QuarantinedChunk> q;
  ASSERT_TRUE((*store)->for_each_quarantined([&](const QuarantinedChunk& c) { q.push_back(c); }).ok());
  ASSERT_EQ(q.size(), 1u);
  EXPECT_EQ(q[0].pos, bad_cp);
  EXPECT_EQ(q[0].revision, 5u);
  EXPECT_EQ(q[0].blob, bad_blob);
  EXPECT_FALSE(q[0].reason.empty());
  auto now = (*store)->load_chunk(bad_cp);
  ASSERT_TRUE(now.ok()) << now.error().message;
  ASSERT_TRUE(now->has_value());
  EXPECT_EQ((*now)->revision, 7u);
  EXPECT_EQ((*now)->chunk.get(local_of(Vec3i{1001, 11, 1001})), make_voxel(materials::kSnow, 200));
}

TEST_F(ServerTest, AFarHolderOfACoarseMipIsRefreshedWhenItsDamagedRowIsQuarantined) {
  // A stored chunk at revision 5 whose row is later damaged: its coarse
  // image entry still says 5, and a far client is served that.
  const Vec3i far_cp{37, 0, 31};
  Vec3i x = far_cp;
  {
    auto world = World::create(dir_.string(), default_world_meta());
    ASSERT_TRUE(world.ok()) << world.error().message;
    for (x.y = 7; x.y >= -4 && (*world)->generate_chunk(x).empty(); --x.y) {
    }
    const Chunk c = (*world)->generate_chunk(x);
    ASSERT_FALSE(c.empty());
    ASSERT_TRUE((*world)->store().save_chunks(std::vector<ChunkWrite>{{x, 5, encode_chunk_blob(c), coarse_voxels(&c)}}).ok());
  }
  run_sql(dir_, "UPDATE chunks SET data = substr(data, 1, length(data) / 2) WHERE cx = " + std::to_string(x.x) +
                    " AND cy = " + std::to_string(x.y) + " AND cz = " + std::to_string(x.z));
  start();
  auto far = join("far");
  const Vec3f far_at{1000.5f, static_cast<float>(x.y * 32 + 16), 1000.5f};
  ASSERT_GT(desired_level(far_at, x, 32), 2) << "the chunk must be held at its coarsest";
  ASSERT_TRUE(far->send(build_client_state(ClientStateMsg{far_at, 300, 32})));
  // Reads far's stream until chunk x is held at `revision`.
  StreamDecodeScratch scratch;
  const auto wait_for_revision = [&](std::uint64_t revision) {
    // Other frames (pushed hashes, presence) keep coming: bounded by a deadline.
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    while (std::chrono::steady_clock::now() < deadline) {
      auto f = far->next_of(wire::Body::StreamBatch);
      if (!f) return false;
      auto r = parse_stream_batch(*msg(*f).body_as_StreamBatch());
      if (!r) return false;
      bool seen = false;
      if (!decode_stream_batch(*r, scratch, [&](const StreamRecord& rec) -> Status {
             seen = seen || (rec.chunk_pos == x && rec.revision == revision && rec.kind != StreamRecordKind::kReleased);
             return Ok{};
           }))
        return false;
      if (seen) return true;
    }
    return false;
  };
  ASSERT_TRUE(wait_for_revision(5)) << "served from the image";
  // Someone near wants it whole: the load finds the row damaged,
  // quarantines it and generates it at 6; the far holder is told.
  auto near = join("near");
  const Vec3i o = chunk_origin(x) + Vec3i{16, 16, 16};
  ASSERT_TRUE(hold_full(*near, Vec3f{static_cast<float>(o.x), static_cast<float>(o.y), static_cast<float>(o.z)}, x));
  EXPECT_TRUE(wait_for_revision(6)) << "the far holder kept the damaged row's revision";
}

TEST_F(ServerTest, EpochAndRevisionsOnlyGrowAcrossRestarts) {
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  const Vec3f pos{1002.0f, 12.0f, 1002.0f};
  auto join_epoch = [&](RawPeer& p) -> std::uint64_t {
    EXPECT_TRUE(p.send(build_hello(HelloMsg{kProtocolVersion, "restarts", "", {}})));
    auto w = p.next_of(wire::Body::Welcome);
    if (!w) return 0;
    auto parsed = parse_welcome(*msg(*w).body_as_Welcome());
    return parsed ? parsed->server_epoch : 0;
  };
  std::uint64_t epoch = 0, acked_revision = 0;
  for (int run = 0; run < 3; ++run) {
    start();
    RawPeer p(server_->port());
    ASSERT_TRUE(p.connected());
    const std::uint64_t e = join_epoch(p);
    if (run > 0) {
      EXPECT_EQ(e, epoch + 1) << "run " << run;
    }
    epoch = e;
    const auto revs = full_revisions(p, pos, {cp});
    ASSERT_EQ(revs.size(), 1u);
    // What the last acknowledged edit's update said, at least.
    EXPECT_GE(revs.at(key(cp)), acked_revision) << "run " << run;
    const EditRequestMsg edit = testing_support::fill_box_edit(static_cast<std::uint32_t>(run + 1), Region{{1000 + run, 10, 1000}, {1001 + run, 11, 1001}}, materials::kBrick, static_cast<std::uint8_t>(100 + run));
    ASSERT_TRUE(p.send(build_edit_request(edit)));
    auto both = p.next_of_both(wire::Body::EditAck, wire::Body::UpdateBatch);
    ASSERT_TRUE(both.has_value());
    auto batch = parse_update_batch(*msg(both->second).body_as_UpdateBatch());
    ASSERT_TRUE(batch.ok());
    ASSERT_EQ(batch->revisions.size(), 1u);
    EXPECT_EQ(batch->revisions[0].chunk_pos, cp);
    EXPECT_GT(batch->revisions[0].revision, acked_revision);
    acked_revision = batch->revisions[0].revision;
    p.close();
    server_->stop();
    server_.reset();
  }
  // On disk: the epoch of the last start and the last acknowledged revision.
  auto world = World::open(dir_.string());
  ASSERT_TRUE(world.ok());
  EXPECT_EQ((*world)->meta().epoch, epoch);
  auto stored = (*world)->load_chunk(cp);
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->revision, acked_revision);
  for (int run = 0; run < 3; ++run)
    EXPECT_EQ(stored->chunk.get(local_of(Vec3i{1000 + run, 10, 1000})),
              make_voxel(materials::kBrick, static_cast<std::uint8_t>(100 + run)));
  // The settings the promise rests on, on the store's own connection.
  EXPECT_EQ(*dynamic_cast<SqliteStore&>((*world)->store()).pragma("journal_mode"), "wal");
  EXPECT_EQ(*dynamic_cast<SqliteStore&>((*world)->store()).pragma("synchronous"), "2");  // FULL
}

TEST_F(ServerTest, ATickThatCannotBeSavedIsNeitherAcknowledgedNorShown) {
  std::atomic<bool> fatal{false};  // set on the world thread, read here
  ServerOptions o;
  o.world.on_fatal = [&] { fatal = true; };
  std::ostringstream log;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  server_log().sinks().push_back(sink);
  start(o);
  auto p = join("editor");
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  // Another connection holds the write lock past the store's busy timeout.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ / kWorldDatabaseName).string().c_str(), &db), SQLITE_OK);
  sqlite3_busy_timeout(db, 10000);  // a connection opening beside it may hold a lock for a moment
  ASSERT_EQ(sqlite3_exec(db, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  const EditRequestMsg e = testing_support::fill_box_edit(3, Region{{1001, 11, 1001}, {1003, 13, 1003}}, materials::kBrick, 255);
  ASSERT_TRUE(p->send(build_edit_request(e)));
  bool acked = false, batch = false;
  std::vector<std::string> rejected;  // every rejection, in order (one is expected)
  std::string reason;
  std::string seen;  // the body types read, for a failure's message
  while (auto f = p->next()) {
    const wire::Message& m = msg(*f);
    seen += std::string(seen.empty() ? "" : ", ") + wire::EnumNameBody(m.body_type());
    if (m.body_type() == wire::Body::EditAck) acked = true;
    if (m.body_type() == wire::Body::UpdateBatch) batch = true;
    if (m.body_type() == wire::Body::EditReject) {
      auto r = parse_edit_reject(*m.body_as_EditReject());
      rejected.push_back(std::to_string(r->edit_id) + ": " + r->reason);
    }
    if (m.body_type() == wire::Body::Disconnect) {
      reason = *parse_disconnect(*m.body_as_Disconnect());
      break;
    }
  }
  sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr);
  sqlite3_close(db);
  EXPECT_FALSE(acked);
  EXPECT_FALSE(batch);
  std::string all;
  for (const std::string& r : rejected) all += "[" + r + "] ";
  ASSERT_EQ(rejected.size(), 1u) << "rejections: " << all << "; frames read: " << seen;
  EXPECT_NE(rejected[0].find("3: storage failure"), std::string::npos) << all << "; frames read: " << seen;
  EXPECT_EQ(reason, "server storage failure");
  EXPECT_TRUE(fatal.load());  // called before any client is told
  EXPECT_TRUE(server_->storage_failed());
  // The rejected edit is not counted as applied.
  EXPECT_EQ(server_->counters().edits_applied.load(), 0u);
  EXPECT_FALSE(server_->health().ok());  // /health answers 503
  EXPECT_NE(server_->health().text.find("storage failed"), std::string::npos) << server_->health().text;
  server_->stop();
  server_log().sinks().pop_back();
  // The last line says the world was not saved, never that it was.
  EXPECT_EQ(log.str().find("world saved"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("world NOT saved"), std::string::npos) << log.str();
  auto world = World::open(dir_.string());
  ASSERT_TRUE(world.ok());
  auto stored = (*world)->load_chunk(cp);
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->revision, 0u);  // nothing of the failed tick reached the store
}

// --- edit application ----------------------------------------------------------

TEST(ApplyEdit, PaintChangesMaterialButNotOccupancy) {
  Grid g;
  ChangedUnits changed;
  g.fill({{0, 0, 0}, {16, 8, 16}}, make_voxel(materials::kRock, 200));
  EditRequestMsg e;
  e.kind = EditKind::kPaint;
  e.center = {8.0f, 8.0f, 8.0f};
  e.radius = 4.0f;
  e.material = materials::kSnow;
  const double before = total_occupancy(g, {{0, 0, 0}, {16, 16, 16}});
  EXPECT_GT(apply_edit(g, e, {{-64, -64, -64}, {64, 64, 64}}, changed), 0u);
  EXPECT_EQ(total_occupancy(g, {{0, 0, 0}, {16, 16, 16}}), before);
  EXPECT_EQ(g.get({8, 7, 8}), make_voxel(materials::kSnow, 200));
  EXPECT_EQ(g.get({8, 9, 8}), Voxel{});                        // Air stays Air
  EXPECT_EQ(g.get({0, 0, 0}), make_voxel(materials::kRock, 200));  // outside the sphere
}

TEST(ApplyEdit, SmoothingAStepLowersTheTopAndRaisesTheFoot) {
  // A one-voxel step: x < 8 solid up to y 10, x >= 8 solid up to y 5.
  Grid g;
  ChangedUnits changed;
  g.fill({{0, 0, 0}, {8, 10, 16}}, solid(materials::kGrass));
  g.fill({{8, 0, 0}, {16, 5, 16}}, solid(materials::kGrass));
  EditRequestMsg e;
  e.kind = EditKind::kSmooth;
  e.center = {8.0f, 7.5f, 8.0f};
  e.radius = 5.0f;
  e.occupancy = 255;
  const double before = total_occupancy(g, {{0, 0, 0}, {16, 16, 16}});
  EXPECT_GT(apply_edit(g, e, {{-64, -64, -64}, {64, 64, 64}}, changed), 0u);
  // The upper corner lost occupancy, the lower corner gained it and took the
  // neighbours' material; the total moves little (a box filter conserves
  // mass away from the sphere's edge).
  EXPECT_LT(occupancy_fraction(g.get({7, 9, 8})), 1.0f);
  EXPECT_GT(occupancy_fraction(g.get({8, 5, 8})), 0.0f);
  EXPECT_EQ(g.get({8, 5, 8}).material, materials::kGrass);
  EXPECT_NEAR(total_occupancy(g, {{0, 0, 0}, {16, 16, 16}}), before, before * 0.02);
  // Smoothing a flat solid interior changes nothing.
  Grid flat;
  flat.fill({{-16, -16, -16}, {16, 16, 16}}, solid(materials::kRock));
  ChangedUnits none;
  e.center = {0.0f, 0.0f, 0.0f};
  EXPECT_EQ(apply_edit(flat, e, {{-64, -64, -64}, {64, 64, 64}}, none), 0u);
}

TEST(ApplyEdit, WriteBoxWritesExactlyItsVoxels) {
  Grid g;
  ChangedUnits changed;
  EditRequestMsg e;
  e.kind = EditKind::kWriteBox;
  e.box = {{30, 2, -3}, {35, 4, 1}};  // crosses a chunk border in x and z
  for (int i = 0; i < e.box.volume(); ++i)
    e.voxels.push_back(i % 3 == 0 ? Voxel{} : make_voxel(static_cast<Material>(1 + i % 5), static_cast<std::uint8_t>(i * 7)));
  EXPECT_EQ(apply_edit(g, e, {{-64, -64, -64}, {64, 64, 64}}, changed),
            static_cast<std::size_t>(std::count_if(e.voxels.begin(), e.voxels.end(),
                                                   [](Voxel v) { return v != Voxel{}; })));
  std::size_t i = 0;
  for (int y = e.box.min.y; y < e.box.max.y; ++y)
    for (int z = e.box.min.z; z < e.box.max.z; ++z)
      for (int x = e.box.min.x; x < e.box.max.x; ++x) EXPECT_EQ(g.get({x, y, z}), e.voxels[i++]);
  EXPECT_EQ(changed.size(), 4u);  // chunks (0,0,-1) (1,0,-1) (0,0,0) (1,0,0)
}

TEST(ApplyEdit, SphereOccupancyMatchesItsVolume) {
  for (const float r : {3.0f, 5.5f, 10.0f}) {
    Grid g;
    ChangedUnits changed;
    EditRequestMsg e;
    e.kind = EditKind::kFillSphere;
    e.center = {0.3f, 40.7f, -5.2f};
    e.radius = r;
    e.material = materials::kSand;
    const Region all{{-64, -64, -64}, {64, 128, 64}};
    apply_edit(g, e, all, changed);
    const double volume = 4.0 / 3.0 * std::numbers::pi * r * r * r;
    EXPECT_NEAR(total_occupancy(g, e.bounds()), volume, volume * 0.03) << "radius " << r;
    EXPECT_FALSE(changed.empty());
  }
}

TEST(ApplyEdit, DiggingASphereOutOfAFilledSphereLeavesNothing) {
  Grid g;
  ChangedUnits changed;
  EditRequestMsg fill;
  fill.kind = EditKind::kFillSphere;
  fill.center = {8, 8, 8};
  fill.radius = 6;
  fill.material = materials::kRock;
  const Region all{{-32, -32, -32}, {64, 64, 64}};
  apply_edit(g, fill, all, changed);
  EditRequestMsg dig = fill;
  dig.material = kAir;
  dig.radius = 8;
  apply_edit(g, dig, all, changed);
  EXPECT_EQ(total_occupancy(g, all), 0.0);
  EXPECT_EQ(g.chunk_count(), 0u);
}

TEST(ApplyEdit, BoxMarksExactlyTheUnitsItChanges) {
  Grid g;
  ChangedUnits changed;
  EditRequestMsg e;
  e.kind = EditKind::kFillBox;
  e.box = {{2, 0, 0}, {6, 1, 1}};  // spans units x 0 and 1 of chunk (0,0,0)
  e.material = materials::kRock;
  e.occupancy = 255;
  EXPECT_EQ(apply_edit(g, e, Region{{-100, -100, -100}, {100, 100, 100}}, changed), 4u);
  ASSERT_EQ(changed.size(), 1u);
  EXPECT_EQ(changed.begin()->second.count(), 2u);
  EXPECT_TRUE(changed.begin()->second.test(0));
  EXPECT_TRUE(changed.begin()->second.test(1));
  // Writing the same again changes nothing.
  changed.clear();
  EXPECT_EQ(apply_edit(g, e, Region{{-100, -100, -100}, {100, 100, 100}}, changed), 0u);
  EXPECT_TRUE(changed.empty());
  // Clipping applies.
  EXPECT_EQ(apply_edit(g, EditRequestMsg{1, EditKind::kFillBox, {{0, 0, 0}, {8, 1, 1}}, {}, 0, kAir, 0, {}},
                       Region{{0, 0, 0}, {3, 1, 1}}, changed),
            1u);
}

}  // namespace
}  // namespace terrane
