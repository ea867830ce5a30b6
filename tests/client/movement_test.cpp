#include "client/movement.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

WelcomeMsg welcome_at(Vec3f spawn) {
  WelcomeMsg w;
  w.spawn = spawn;
  w.max_view_distance = 200;
  w.max_full_res_radius = 64;
  w.default_view_distance = 128;
  w.default_full_res_radius = 48;
  return w;
}

ClientStateMsg parsed(const Frame& f) {
  auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
  EXPECT_TRUE(m.ok());
  EXPECT_EQ((*m)->body_type(), wire::Body::ClientState);
  auto s = parse_client_state(*(*m)->body_as_ClientState());
  EXPECT_TRUE(s.ok());
  return *s;
}

TEST(Movement, StartsAtTheSpawnPlusTheOffsetOnce) {
  ClientOptions o;
  o.state = ClientStateMsg{{0, 0, 0}, 150, 40};
  o.spawn_offset = {1, 2, 3};
  Movement m(o);
  m.start();
  EXPECT_FALSE(m.last().has_value());
  EXPECT_FALSE(m.session_frame().has_value());
  const auto first = m.welcomed(welcome_at({10, 20, 30}));
  ASSERT_TRUE(first.has_value());
  const ClientStateMsg s = parsed(*first);
  EXPECT_EQ(s.position, (Vec3f{11, 22, 33}));
  EXPECT_EQ(s.view_distance, 150);
  EXPECT_EQ(m.last()->position, (Vec3f{11, 22, 33}));
  EXPECT_FALSE(m.welcomed(welcome_at({0, 0, 0})).has_value());  // a second Welcome moves nothing
}

TEST(Movement, AClientThatMovedFirstOrStartsElsewhereKeepsItsPosition) {
  ClientOptions o;
  o.start_at_spawn = false;
  o.state = ClientStateMsg{{5, 6, 7}, 100, 32};
  Movement m(o);
  m.start();
  ASSERT_TRUE(m.last().has_value());
  EXPECT_FALSE(m.welcomed(welcome_at({0, 0, 0})).has_value());
  const Frame f = m.move(ClientStateMsg{{8, 9, 10}, 100, 32});
  EXPECT_EQ(parsed(f).position, (Vec3f{8, 9, 10}));
  ASSERT_TRUE(m.session_frame().has_value());
  EXPECT_EQ(parsed(*m.session_frame()).position, (Vec3f{8, 9, 10}));  // sent again on a new connection
}

TEST(Movement, AClientThatDoesNotStreamSendsNoState) {
  ClientOptions o;
  o.stream = false;
  Movement m(o);
  m.start();
  EXPECT_FALSE(m.welcomed(welcome_at({0, 0, 0})).has_value());
  EXPECT_FALSE(m.session_frame().has_value());
}

TEST(Movement, TheViewStreamedTakesTheServersDefaultsAndCaps) {
  ClientOptions o;
  o.start_at_spawn = false;
  o.state = ClientStateMsg{{1, 2, 3}, 0, 0};
  Movement m(o);
  const WelcomeMsg w = welcome_at({0, 0, 0});
  EXPECT_FALSE(m.view(w).has_value());
  m.start();
  StreamedView v = *m.view(w);
  EXPECT_EQ(v.view_distance, 128);
  EXPECT_EQ(v.full_res_radius, 48);
  m.move(ClientStateMsg{{1, 2, 3}, 1000, 1000});
  v = *m.view(w);
  EXPECT_EQ(v.view_distance, 200);
  EXPECT_EQ(v.full_res_radius, 64);
  m.move(ClientStateMsg{{1, 2, 3}, 40, 60});
  v = *m.view(w);
  EXPECT_EQ(v.view_distance, 40);
  EXPECT_EQ(v.full_res_radius, 40);  // never beyond the view
  EXPECT_EQ(v.position, (Vec3f{1, 2, 3}));
}

}  // namespace
}  // namespace terrane
