#include "client/view_coverage.h"

#include <algorithm>
#include <optional>

#include "common/world/view.h"

namespace terrane {

StreamedView streamed_view(const ClientStateMsg& s, const WelcomeMsg& w) {
  const std::int32_t view =
      std::min(s.view_distance == 0 ? w.default_view_distance : s.view_distance, w.max_view_distance);
  const std::int32_t full =
      std::min({s.full_res_radius == 0 ? w.default_full_res_radius : s.full_res_radius, w.max_full_res_radius, view});
  return StreamedView{s.position, view, full};
}

namespace {

// Adds (sign 1) or takes away (sign -1) one chunk in view: held in `form`
// (nullopt: not held), wanted at level `wanted`.
void tally(ViewCoverage& out, std::optional<HoldingForm> form, int wanted, int sign) {
  auto add = [sign](std::size_t& n) { n += static_cast<std::size_t>(static_cast<std::ptrdiff_t>(sign)); };
  add(out.in_view);
  if (wanted == 0) add(out.want_full);
  if (!form) {
    add(out.not_held);
    return;
  }
  switch (*form) {
    case HoldingForm::kFull: add(out.full); break;
    case HoldingForm::kEmpty: add(out.empty); break;
    case HoldingForm::kMip1: add(out.mip1); break;
    case HoldingForm::kMip2: add(out.mip2); break;
    case HoldingForm::kMip3: add(out.mip3); break;
    case HoldingForm::kEstimate: add(out.estimate); break;
    case HoldingForm::kHorizon4:
    case HoldingForm::kHorizon5: add(out.horizon); break;
  }
  const Holding h{*form, 0};
  if (h.level() <= wanted) add(out.settled);
  if (wanted == 0 && h.full_resolution()) add(out.held_full);
}

// The chunk offsets of a view's cube, each axis -n..n, and whether a chunk
// is in view: the server's view rule (chunks_in_view, without its order or
// its list). The loops are clamped to the world's vertical bounds (and
// horizontal ones when it has them) before the per-chunk test.
std::int32_t cube_radius(const StreamedView& v) {
  return (std::max(v.view_distance, 0) + kChunkSize / 2) / kChunkSize;
}

template <typename F>
void for_each_in_view(const StreamedView& v, const WorldBounds& bounds, F&& fn) {
  const Vec3i center = view_chunk(v.position);
  const std::int32_t n = cube_radius(v);
  Vec3i lo{-n, -n, -n}, hi{n, n, n};
  // Chunk c touches [min, max) when c*32 < max and c*32 + 32 > min.
  auto clamp_axis = [](std::int32_t c, std::int32_t& lo_o, std::int32_t& hi_o, std::int32_t min, std::int32_t max) {
    auto chunk_of = [](std::int64_t w) { return w >= 0 ? w / kChunkSize : -((-w + kChunkSize - 1) / kChunkSize); };
    const std::int64_t first = chunk_of(min);
    const std::int64_t last = chunk_of(std::int64_t{max} - 1);
    lo_o = static_cast<std::int32_t>(std::max<std::int64_t>(lo_o, first - c));
    hi_o = static_cast<std::int32_t>(std::min<std::int64_t>(hi_o, last - c));
  };
  clamp_axis(center.y, lo.y, hi.y, bounds.min_y, bounds.max_y);
  if (bounds.bounded_xz) {
    clamp_axis(center.x, lo.x, hi.x, bounds.min_x, bounds.max_x);
    clamp_axis(center.z, lo.z, hi.z, bounds.min_z, bounds.max_z);
  }
  Vec3i o;
  for (o.y = lo.y; o.y <= hi.y; ++o.y)
    for (o.z = lo.z; o.z <= hi.z; ++o.z)
      for (o.x = lo.x; o.x <= hi.x; ++o.x)
        if (offset_within(o, v.view_distance)) fn(center + o, o);
}

std::optional<HoldingForm> form_of(const Holding* h) {
  if (h == nullptr) return std::nullopt;
  return h->form;
}

}  // namespace

ViewCoverage coverage(const Replica& replica, const StreamedView& v, const WorldBounds& bounds) {
  ViewCoverage out;
  for_each_in_view(v, bounds, [&](Vec3i cp, Vec3i o) {
    tally(out, form_of(replica.holding(cp)), offset_level(o, v.full_res_radius), 1);
  });
  out.complete = out.settled == out.in_view;
  return out;
}

ViewCoverageCounter::ViewCoverageCounter(const StreamedView& view, const WorldBounds& bounds, const Replica& replica)
    : view_(view), bounds_(bounds), center_(view_chunk(view.position)) {
  for_each_in_view(view, bounds, [&](Vec3i cp, Vec3i o) {
    const std::optional<HoldingForm> f = form_of(replica.holding(cp));
    if (f) held_.insert_or_assign(cp, *f);
    tally(coverage_, f, offset_level(o, view_.full_res_radius), 1);
  });
  coverage_.complete = coverage_.settled == coverage_.in_view;
}

void ViewCoverageCounter::update(Vec3i cp, const Holding* now) {
  const Vec3i o = cp - center_;
  if (!offset_within(o, view_.view_distance) || !bounds_.touches_chunk(cp)) return;
  const auto it = held_.find(cp);
  const std::optional<HoldingForm> was = it == held_.end() ? std::nullopt : std::optional(it->second);
  const std::optional<HoldingForm> is = form_of(now);
  if (is == was) return;
  const int wanted = offset_level(o, view_.full_res_radius);
  tally(coverage_, was, wanted, -1);
  tally(coverage_, is, wanted, 1);
  if (is)
    held_.insert_or_assign(cp, *is);
  else
    held_.erase(cp);
  coverage_.complete = coverage_.settled == coverage_.in_view;
}

}  // namespace terrane
