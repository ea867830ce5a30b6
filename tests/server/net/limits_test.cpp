// Hostile input and limits: each offender is dropped with the right reason
// while a well-behaved client on the same server keeps being served (its
// edits acknowledged and broadcast back to it).
#include "server/net/limits.h"

#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <thread>

#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::msg;
using testing_support::RawPeer;
using testing_support::ServerTest;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

class LimitsTest : public ServerTest {
 protected:
  // A client at a fixed place holding it at full resolution.
  std::unique_ptr<RawPeer> good_peer() {
    auto p = join("good");
    EXPECT_TRUE(hold_full(*p, kHome, chunk_of(Vec3i{1002, 12, 1002})));
    return p;
  }
  // The good client edits and hears both the ack and the update.
  void expect_served(RawPeer& p) {
    EditRequestMsg e;
    e.edit_id = ++edit_id_;
    e.kind = EditKind::kFillBox;
    const int y = 10 + static_cast<int>(edit_id_ % 4);
    e.box = {{1001, y, 1001}, {1003, y + 1, 1003}};
    e.material = static_cast<Material>(1 + edit_id_ % 8);
    e.occupancy = 255;
    ASSERT_TRUE(p.send(build_edit_request(e)));
    auto both = p.next_of_both(wire::Body::EditAck, wire::Body::UpdateBatch);
    ASSERT_TRUE(both.has_value()) << "the good client lost its connection";
    EXPECT_EQ(msg(both->first).body_as_EditAck()->edit_id(), e.edit_id);
  }
  static std::string reason_of(RawPeer& p) {
    auto f = p.next_of(wire::Body::Disconnect);
    if (!f) return "(no disconnect)";
    auto r = parse_disconnect(*msg(*f).body_as_Disconnect());
    return r ? *r : "(bad reason)";
  }
  static constexpr Vec3f kHome{1002.0f, 12.0f, 1002.0f};
  std::uint32_t edit_id_ = 0;
};

TEST_F(LimitsTest, PerPlayerTokensAdmitOnlyTheirPlayer) {
  ServerOptions o;
  o.ops.player_tokens = {{"good", {"g-token", false}}, {"bob", {"b-token", false}}};
  start(o);
  RawPeer good(server_->port());
  ASSERT_TRUE(good.send(build_hello(HelloMsg{kProtocolVersion, "good", "g-token", {}})));
  ASSERT_TRUE(good.next_of(wire::Body::Welcome).has_value());
  ASSERT_TRUE(hold_full(good, kHome, chunk_of(Vec3i{1002, 12, 1002})));
  for (const auto& [name, token] : std::vector<std::pair<std::string, std::string>>{
           {"bob", "g-token"}, {"mallory", "b-token"}, {"bob", ""}}) {
    RawPeer bad(server_->port());
    ASSERT_TRUE(bad.send(build_hello(HelloMsg{kProtocolVersion, name, token, {}})));
    EXPECT_EQ(reason_of(bad), "authentication failed") << name;
    EXPECT_TRUE(bad.closed_by_server());
  }
  RawPeer bob(server_->port());
  ASSERT_TRUE(bob.send(build_hello(HelloMsg{kProtocolVersion, "bob", "b-token", {}})));
  EXPECT_TRUE(bob.next_of(wire::Body::Welcome).has_value());
  expect_served(good);
  EXPECT_EQ(server_->counters().auth_failures.load(), 3u);
}

TEST_F(LimitsTest, AnOpenServerIsRefusedBeyondLoopback) {
  ServerOptions o;
  o.world_dir = dir_.string();
  o.net.bind_address = "0.0.0.0";  // refused before anything is bound
  auto s = Server::create(o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("without authentication"), std::string::npos) << s.error().message;
  EXPECT_TRUE(is_loopback_address("127.0.0.1"));
  EXPECT_TRUE(is_loopback_address("::1"));
  EXPECT_FALSE(is_loopback_address("10.1.2.3"));
}

TEST_F(LimitsTest, TokensFileErrorsNameFileAndLine) {
  const fs::path f = fs::temp_directory_path() / ("terrane-tokens-" + std::to_string(::getpid()));
  {
    std::ofstream(f) << "# players\nalice s3cret\n\nbob\n";
  }
  auto r = load_tokens_file(f.string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(f.string() + ":4:"), std::string::npos) << r.error().message;
  {
    std::ofstream(f) << "alice s3cret admin\nbob hunter2\ncarol c player\n";
  }
  r = load_tokens_file(f.string());
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->at("bob").token, "hunter2");
  EXPECT_FALSE(r->at("bob").admin);
  EXPECT_TRUE(r->at("alice").admin);
  EXPECT_FALSE(r->at("carol").admin);
  {
    std::ofstream(f) << "alice a owner\n";
  }
  r = load_tokens_file(f.string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(":1: role 'owner' is neither player nor admin"), std::string::npos)
      << r.error().message;
  {
    std::ofstream(f) << "alice a\nalice b\n";
  }
  EXPECT_FALSE(load_tokens_file(f.string()).ok());
  // A comment may end any line ('#' opening a word); a '#' inside a token
  // is part of it.
  {
    std::ofstream(f) << "alice s3cret admin  # the operator\nbob hunt#er2 # a player\n  # indented\ncarol c #\n";
  }
  r = load_tokens_file(f.string());
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_TRUE(r->at("alice").admin);
  EXPECT_EQ(r->at("bob").token, "hunt#er2");
  EXPECT_EQ(r->at("carol").token, "c");
  EXPECT_EQ(r->size(), 3u);
  {
    std::ofstream(f) << "dave # no token\n";
  }
  r = load_tokens_file(f.string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(":1: player 'dave' has no token"), std::string::npos) << r.error().message;
  fs::remove(f);
}

TEST(Networks, CanonicalFormsAndMembership) {
  EXPECT_EQ(canonical_network("10.1.2.3/8"), "10.0.0.0/8");
  EXPECT_EQ(canonical_network("2001:DB8::1/32"), "2001:db8::/32");
  EXPECT_EQ(canonical_network("0.0.0.0/0"), "0.0.0.0/0");
  EXPECT_EQ(canonical_network("10.0.0.1"), std::nullopt) << "an address is not a network";
  EXPECT_EQ(canonical_network("10.0.0.0/33"), std::nullopt);
  EXPECT_EQ(canonical_network("alice/8"), std::nullopt);
  EXPECT_TRUE(address_in_network("10.200.3.4", "10.0.0.0/8"));
  EXPECT_FALSE(address_in_network("11.0.0.1", "10.0.0.0/8"));
  EXPECT_TRUE(address_in_network("1.2.3.4", "0.0.0.0/0"));
  EXPECT_TRUE(address_in_network("2001:db8:ffff::9", "2001:db8::/32"));
  EXPECT_FALSE(address_in_network("2001:db9::1", "2001:db8::/32"));
  EXPECT_FALSE(address_in_network("10.0.0.1", "2001:db8::/32")) << "families never mix";
  EXPECT_FALSE(address_in_network("not an address", "10.0.0.0/8"));
}

TEST_F(LimitsTest, SlowlorisFramesAreDropped) {
  ServerOptions o;
  o.net.session.frame_timeout = 300ms;
  start(o);
  auto good = good_peer();
  auto slow = join("slow");
  const Frame ping = build_ping(1);
  ASSERT_TRUE(slow->send(std::span<const std::uint8_t>(ping).first(3)));  // and nothing more
  EXPECT_NE(reason_of(*slow).find("frame not completed"), std::string::npos);
  // Before the handshake too.
  RawPeer early(server_->port());
  const Frame hello = build_hello(HelloMsg{kProtocolVersion, "early", "", {}});
  ASSERT_TRUE(early.send(std::span<const std::uint8_t>(hello).first(hello.size() - 1)));
  EXPECT_NE(reason_of(early).find("frame not completed"), std::string::npos);
  expect_served(*good);
}

TEST_F(LimitsTest, EditFloodIsDropped) {
  ServerOptions o;
  o.world.edits_per_second = 5;
  start(o);
  auto good = good_peer();
  auto flood = join("flood");
  ASSERT_TRUE(hold_full(*flood, kHome, chunk_of(Vec3i{1002, 12, 1002})));
  EditRequestMsg e;
  e.kind = EditKind::kFillBox;
  e.box = {{1000, 20, 1000}, {1001, 21, 1001}};
  e.material = materials::kSand;
  e.occupancy = 255;
  for (std::uint32_t i = 1; i <= 50; ++i) {
    e.edit_id = i;
    if (!flood->send(build_edit_request(e))) break;
  }
  EXPECT_NE(reason_of(*flood).find("edit rate limit"), std::string::npos);
  EXPECT_GE(server_->counters().limit_violations.load(), 1u);
  expect_served(*good);
}

TEST_F(LimitsTest, TeleportingIsDropped) {
  ServerOptions o;
  o.replication.max_speed = 100;
  start(o);
  auto good = good_peer();
  auto jumper = join("jumper");
  ASSERT_TRUE(jumper->send(build_client_state(ClientStateMsg{{0.5f, 40.0f, 0.5f}, 32, 16})));
  ASSERT_TRUE(jumper->send(build_client_state(ClientStateMsg{{20.5f, 40.0f, 0.5f}, 32, 16})));  // a walk
  ASSERT_TRUE(jumper->send(build_client_state(ClientStateMsg{{5000.5f, 40.0f, 0.5f}, 32, 16})));
  EXPECT_NE(reason_of(*jumper).find("moving too fast"), std::string::npos);
  expect_served(*good);
}

TEST_F(LimitsTest, InboundByteFloodIsDropped) {
  ServerOptions o;
  o.net.session.inbound_bytes_per_second = 64 * 1024;
  o.net.session.inbound_burst_bytes = 128 * 1024;
  start(o);
  auto good = good_peer();
  auto hose = join("hose");
  Frame pings;
  for (int i = 0; i < 4000; ++i) {
    const Frame p = build_ping(static_cast<std::uint64_t>(i));
    pings.insert(pings.end(), p.begin(), p.end());
  }
  for (int i = 0; i < 20 && hose->send(pings); ++i) {
  }
  EXPECT_NE(reason_of(*hose).find("inbound rate limit"), std::string::npos);
  expect_served(*good);
}

TEST_F(LimitsTest, GarbageAndOutOfRangeValuesAreRefused) {
  start();
  auto good = good_peer();
  // Garbage after the handshake.
  auto junk = join("junk");
  std::mt19937 rng(7);
  std::vector<std::uint8_t> bytes(64);
  for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
  bytes[0] = 40;  // a plausible length, then nonsense
  bytes[1] = bytes[2] = bytes[3] = 0;
  ASSERT_TRUE(junk->send(bytes));
  EXPECT_NE(reason_of(*junk).find("protocol error"), std::string::npos);
  // A position far outside the wire's range.
  auto far = join("far");
  ASSERT_TRUE(far->send(build_client_state(ClientStateMsg{{1e9f, 0.0f, 0.0f}, 32, 16})));
  EXPECT_NE(reason_of(*far).find("position out of range"), std::string::npos);
  // An unknown material is rejected, not fatal.
  auto painter = join("painter");
  ASSERT_TRUE(hold_full(*painter, kHome, chunk_of(Vec3i{1002, 12, 1002})));
  flatbuffers::FlatBufferBuilder fbb;
  const wire::Vec3i mn(1001, 10, 1001), mx(1002, 11, 1002);
  auto edit = wire::CreateEditRequest(fbb, 5, wire::EditKind::FillBox, &mn, &mx, nullptr, 0, 70, 255);
  fbb.Finish(wire::CreateMessage(fbb, wire::Body::EditRequest, edit.Union()));
  Frame raw;
  append_frame(std::span<const std::uint8_t>(fbb.GetBufferPointer(), fbb.GetSize()), raw);
  ASSERT_TRUE(painter->send(raw));
  auto rej = painter->next_of(wire::Body::EditReject);
  ASSERT_TRUE(rej.has_value());
  EXPECT_NE(parse_edit_reject(*msg(*rej).body_as_EditReject())->reason.find("material"), std::string::npos);
  // A material the wire allows (< 64) but this world does not define.
  EditRequestMsg e;
  e.edit_id = 6;
  e.kind = EditKind::kFillBox;
  e.box = {{1001, 10, 1001}, {1002, 11, 1002}};
  e.material = static_cast<Material>(default_material_names().size());
  e.occupancy = 255;
  ASSERT_TRUE(painter->send(build_edit_request(e)));
  rej = painter->next_of(wire::Body::EditReject);
  ASSERT_TRUE(rej.has_value());
  EXPECT_NE(parse_edit_reject(*msg(*rej).body_as_EditReject())->reason.find("unknown material"), std::string::npos)
      << parse_edit_reject(*msg(*rej).body_as_EditReject())->reason;
  expect_served(*good);
}

TEST_F(LimitsTest, OversizedEditsAreRejectedAndExtraClientsTurnedAway) {
  ServerOptions o;
  o.replication.max_edit_voxels = 100;
  o.net.max_clients = 2;
  start(o);
  auto good = good_peer();
  EditRequestMsg e;
  e.edit_id = 900;
  e.kind = EditKind::kFillBox;
  e.box = {{1000, 10, 1000}, {1005, 15, 1005}};  // 125 voxels
  e.material = materials::kSand;
  e.occupancy = 255;
  ASSERT_TRUE(good->send(build_edit_request(e)));
  auto rej = good->next_of(wire::Body::EditReject);
  ASSERT_TRUE(rej.has_value());
  EXPECT_NE(parse_edit_reject(*msg(*rej).body_as_EditReject())->reason.find("larger than 100"), std::string::npos);
  auto second = join("second");
  RawPeer third(server_->port());
  EXPECT_EQ(reason_of(third), "server full");
  expect_served(*good);
}

}  // namespace
}  // namespace terrane
