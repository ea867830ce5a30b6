#include "protocol/messages.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <tuple>

#include "common/codec/byte_rle.h"
#include "common/codec/net_codec.h"
#include "common/world/coarse_image.h"
#include "protocol/chunk_hash.h"
#include "protocol/region_claims.h"

namespace terrane {

std::size_t control_character_at(std::string_view text) {
  const auto bad =
      std::find_if(text.begin(), text.end(), [](char ch) { return static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f; });
  return bad == text.end() ? std::string_view::npos : static_cast<std::size_t>(bad - text.begin());
}

namespace {

using flatbuffers::FlatBufferBuilder;

template <class T>
Frame finish(FlatBufferBuilder& fbb, flatbuffers::Offset<T> body) {
  auto msg = wire::CreateMessage(fbb, wire::BodyTraits<T>::enum_value, body.Union());
  fbb.Finish(msg);
  Frame out;
  out.reserve(kFrameHeaderBytes + fbb.GetSize());
  append_frame(std::span<const std::uint8_t>(fbb.GetBufferPointer(), fbb.GetSize()), out);
  return out;
}

// Finishes a message whose byte vector vec was made first and left
// uninitialised: FlatBuffers builds back to front, so the vector's bytes
// are the buffer's last but its padding, after every table. The frame is
// then the bytes before them (frame header, tables, the vector's length),
// data's segments, and the padding: the bytes finish() would make had data
// been copied into vec.
template <class T>
OutFrame finish_around(FlatBufferBuilder& fbb, flatbuffers::Offset<T> body, flatbuffers::uoffset_t vec, OutFrame data) {
  auto msg = wire::CreateMessage(fbb, wire::BodyTraits<T>::enum_value, body.Union());
  fbb.Finish(msg);
  const std::span<const std::uint8_t> buf(fbb.GetBufferPointer(), fbb.GetSize());
  // An offset counts from the buffer's end and points at the length.
  const std::size_t at = buf.size() - vec + sizeof(flatbuffers::uoffset_t);
  const auto n = static_cast<std::uint32_t>(buf.size());  // the frame header: the whole body's length
  Frame head = {static_cast<std::uint8_t>(n), static_cast<std::uint8_t>(n >> 8), static_cast<std::uint8_t>(n >> 16),
                static_cast<std::uint8_t>(n >> 24)};
  head.insert(head.end(), buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(at));
  data.append(buf.subspan(at + data.size()));
  data.prepend(std::move(head));
  return data;
}

wire::Vec3i to_wire(Vec3i v) { return wire::Vec3i(v.x, v.y, v.z); }
wire::Vec3f to_wire(Vec3f v) { return wire::Vec3f(v.x, v.y, v.z); }
Vec3i from_wire(const wire::Vec3i& v) { return {v.x(), v.y(), v.z()}; }
Vec3f from_wire(const wire::Vec3f& v) { return {v.x(), v.y(), v.z()}; }

std::string_view clip(std::string_view s, std::size_t limit) { return s.substr(0, std::min(s.size(), limit)); }

DecodeError invalid(const char* what) { return DecodeError{DecodeErrorCode::kInvalidValue, 0, what}; }
DecodeError over(const char* what) { return DecodeError{DecodeErrorCode::kOverLimit, 0, what}; }

bool has_control_character(std::string_view text) { return control_character_at(text) != std::string_view::npos; }

bool finite(Vec3f v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
bool position_ok(Vec3f v) {
  const auto lim = static_cast<float>(kMaxWireCoordinate);
  return finite(v) && std::fabs(v.x) <= lim && std::fabs(v.y) <= lim && std::fabs(v.z) <= lim;
}

// ChunkRevision and HeldChunk both start with a Vec3i at byte 0 and a ulong
// at byte 16; read bytewise (the struct may sit misaligned in a buffer).
ChunkRevisionMsg read_chunk_and_revision(const std::uint8_t* e) {
  std::int32_t xyz[3];
  std::uint64_t rev;
  std::memcpy(xyz, e, sizeof xyz);
  std::memcpy(&rev, e + 16, sizeof rev);
  return {{flatbuffers::EndianScalar(xyz[0]), flatbuffers::EndianScalar(xyz[1]), flatbuffers::EndianScalar(xyz[2])},
          flatbuffers::EndianScalar(rev)};
}

std::span<const std::uint8_t> bytes_of(const flatbuffers::Vector<std::uint8_t>* v) {
  if (v == nullptr) return {};
  return {v->data(), v->size()};
}

}  // namespace

bool wire_coordinate_ok(Vec3i v) {
  auto ok = [](std::int32_t c) { return c >= -kMaxWireCoordinate && c <= kMaxWireCoordinate; };
  return ok(v.x) && ok(v.y) && ok(v.z);
}

bool wire_chunk_ok(Vec3i c) {
  constexpr std::int32_t lim = kMaxWireCoordinate / kChunkSize;
  auto ok = [](std::int32_t v) { return v >= -lim && v <= lim; };
  return ok(c.x) && ok(c.y) && ok(c.z);
}

Region EditRequestMsg::reads() const {
  Region r = bounds();
  if (kind == EditKind::kSmooth) {
    r.min = r.min - Vec3i{1, 1, 1};
    r.max = r.max + Vec3i{1, 1, 1};
  }
  return r;
}

Region EditRequestMsg::bounds() const {
  if (!is_sphere_edit(kind)) return box;
  // Every voxel whose cube may overlap the sphere (with the half-voxel edge
  // band used for fractional occupancy).
  const float r = radius + 1.0f;
  const Vec3i lo{static_cast<std::int32_t>(std::floor(center.x - r)), static_cast<std::int32_t>(std::floor(center.y - r)),
                 static_cast<std::int32_t>(std::floor(center.z - r))};
  const Vec3i hi{static_cast<std::int32_t>(std::ceil(center.x + r)), static_cast<std::int32_t>(std::ceil(center.y + r)),
                 static_cast<std::int32_t>(std::ceil(center.z + r))};
  return {lo, hi};
}

// --- builders ------------------------------------------------------------------

Frame build_hello(const HelloMsg& m) {
  FlatBufferBuilder fbb(128);
  const auto name = fbb.CreateString(clip(m.client_name, kMaxClientNameBytes));
  const auto token = fbb.CreateString(clip(m.auth_token, kMaxAuthTokenBytes));
  const auto resume = m.resume_token.empty() ? 0 : fbb.CreateString(clip(m.resume_token, kMaxResumeTokenBytes));
  return finish(fbb, wire::CreateHello(fbb, m.protocol_version, name, token, resume, m.features));
}

Frame build_welcome(const WelcomeMsg& m) {
  FlatBufferBuilder fbb(1024);
  std::vector<flatbuffers::Offset<flatbuffers::String>> names;
  for (std::size_t i = 0; i < m.materials.size() && i < kMaxMaterialNames; ++i)
    names.push_back(fbb.CreateString(clip(m.materials[i], kMaxClientNameBytes)));
  const auto spawn = to_wire(m.spawn);
  return finish(fbb, wire::CreateWelcomeDirect(fbb, m.protocol_version, m.server_epoch, &spawn, &names, m.bounds_min_y,
                                               m.bounds_max_y, m.max_view_distance, m.max_full_res_radius,
                                               m.max_frame_bytes, m.tick_hz, m.bounded_xz, m.bounds_min_x,
                                               m.bounds_min_z, m.bounds_max_x, m.bounds_max_z, m.default_view_distance,
                                               m.default_full_res_radius, m.edits_per_second, m.edit_burst,
                                               m.server_id, m.world_id));
}

Frame build_disconnect(std::string_view reason) {
  FlatBufferBuilder fbb(128);
  const auto r = fbb.CreateString(clip(reason, kMaxReasonBytes));
  return finish(fbb, wire::CreateDisconnect(fbb, r));
}

Frame build_admin_request(const AdminRequestMsg& m) {
  FlatBufferBuilder fbb(256);
  const auto cmd = fbb.CreateString(m.command);
  std::vector<flatbuffers::Offset<flatbuffers::String>> args;
  for (const auto& a : m.args) args.push_back(fbb.CreateString(a));
  const auto av = fbb.CreateVector(args);
  return finish(fbb, wire::CreateAdminRequest(fbb, m.request_id, cmd, av));
}

Frame build_admin_result(const AdminResultMsg& m) {
  // Leave room for the frame header and the table within the default frame cap.
  constexpr std::size_t kRoom = kDefaultMaxFrameBytes - 4096;
  const std::string_view text = clip(m.text, kRoom / 2);
  const std::string_view json = m.json.size() <= kRoom / 2 ? std::string_view(m.json) : std::string_view("{}");
  FlatBufferBuilder fbb(text.size() + json.size() + 128);
  const auto t = fbb.CreateString(text);
  const auto j = fbb.CreateString(json);
  return finish(fbb, wire::CreateAdminResult(fbb, m.request_id, m.ok, t, j));
}

Frame build_server_notice(const ServerNoticeMsg& m) {
  FlatBufferBuilder fbb(m.text.size() + 64);
  const auto t = fbb.CreateString(clip(m.text, kMaxNoticeBytes));
  return finish(fbb, wire::CreateServerNotice(fbb, m.kind, t, m.seconds_left, m.reconnect));
}

Frame build_redirect(const RedirectMsg& m) {
  FlatBufferBuilder fbb(128);
  const auto h = fbb.CreateString(clip(m.host, kMaxRedirectHostBytes));
  const auto t = fbb.CreateString(clip(m.token, kMaxResumeTokenBytes));
  return finish(fbb, wire::CreateRedirect(fbb, m.server_id, h, m.port, t));
}

Frame build_client_state(const ClientStateMsg& m) {
  FlatBufferBuilder fbb(64);
  const auto pos = to_wire(m.position);
  return finish(fbb, wire::CreateClientState(fbb, &pos, m.view_distance, m.full_res_radius));
}

Frame build_update_batch(std::uint64_t tick, std::span<const std::uint8_t> data,
                         std::span<const ChunkRevisionMsg> revisions) {
  FlatBufferBuilder fbb(data.size() + revisions.size() * 24 + 64);
  std::vector<wire::ChunkRevision> revs;
  revs.reserve(revisions.size());
  for (const auto& r : revisions) revs.emplace_back(to_wire(r.chunk_pos), r.revision);
  const auto d = fbb.CreateVector(data.data(), data.size());
  const auto rv = fbb.CreateVectorOfStructs(revs);
  return finish(fbb, wire::CreateUpdateBatch(fbb, tick, d, rv));
}

OutFrame gather_update_batch(std::uint64_t tick, OutFrame data, std::span<const ChunkRevisionMsg> revisions) {
  // Room for the vector left uninitialised too (one allocation, untouched).
  FlatBufferBuilder fbb(data.size() + revisions.size() * 24 + 64);
  std::vector<wire::ChunkRevision> revs;
  revs.reserve(revisions.size());
  for (const auto& r : revisions) revs.emplace_back(to_wire(r.chunk_pos), r.revision);
  std::uint8_t* unused = nullptr;
  const auto d = fbb.CreateUninitializedVector(data.size(), &unused);
  const auto rv = fbb.CreateVectorOfStructs(revs);
  return finish_around(fbb, wire::CreateUpdateBatch(fbb, tick, d, rv), d.o, std::move(data));
}

Frame build_edit_request(const EditRequestMsg& m) {
  std::vector<std::uint8_t> rle;
  if (m.kind == EditKind::kWriteBox) byte_rle_encode(m.voxels, rle);
  FlatBufferBuilder fbb(128 + rle.size());
  const auto mn = to_wire(m.box.min);
  const auto mx = to_wire(m.box.max);
  const auto c = to_wire(m.center);
  const auto data = rle.empty() ? flatbuffers::Offset<flatbuffers::Vector<std::uint8_t>>()
                                : fbb.CreateVector(rle.data(), rle.size());
  return finish(fbb, wire::CreateEditRequest(fbb, m.edit_id, static_cast<wire::EditKind>(m.kind), &mn, &mx, &c,
                                             m.radius, m.material, m.occupancy, data));
}

Frame build_edit_ack(std::uint32_t edit_id, std::uint64_t tick) {
  FlatBufferBuilder fbb(64);
  return finish(fbb, wire::CreateEditAck(fbb, edit_id, tick));
}

Frame build_edit_reject(std::uint32_t edit_id, std::string_view reason, bool outcome_unknown) {
  FlatBufferBuilder fbb(128);
  const auto r = fbb.CreateString(clip(reason, kMaxReasonBytes));
  return finish(fbb, wire::CreateEditReject(fbb, edit_id, r, nullptr, nullptr, 0, outcome_unknown));
}

Frame build_edit_reject(std::uint32_t edit_id, std::string_view reason, const Region& box,
                        std::span<const Voxel> voxels, bool outcome_unknown) {
  std::vector<std::uint8_t> rle;
  byte_rle_encode(voxels, rle);
  FlatBufferBuilder fbb(128 + rle.size());
  const auto r = fbb.CreateString(clip(reason, kMaxReasonBytes));
  const auto mn = to_wire(box.min);
  const auto mx = to_wire(box.max);
  const auto d = fbb.CreateVector(rle.data(), rle.size());
  return finish(fbb, wire::CreateEditReject(fbb, edit_id, r, &mn, &mx, d, outcome_unknown));
}

Frame build_read_box(std::uint32_t request_id, const Region& box) {
  FlatBufferBuilder fbb(64);
  const auto mn = to_wire(box.min);
  const auto mx = to_wire(box.max);
  return finish(fbb, wire::CreateReadBox(fbb, request_id, &mn, &mx));
}

Frame build_read_box_result(std::uint32_t request_id, const Region& box, std::span<const Voxel> voxels) {
  std::vector<std::uint8_t> rle;
  byte_rle_encode(voxels, rle);
  FlatBufferBuilder fbb(128 + rle.size());
  const auto mn = to_wire(box.min);
  const auto mx = to_wire(box.max);
  const auto d = fbb.CreateVector(rle.data(), rle.size());
  return finish(fbb, wire::CreateReadBoxResult(fbb, request_id, &mn, &mx, d));
}

Frame build_read_box_error(std::uint32_t request_id, const Region& box, std::string_view error) {
  FlatBufferBuilder fbb(128);
  const auto mn = to_wire(box.min);
  const auto mx = to_wire(box.max);
  const auto e = fbb.CreateString(clip(error.empty() ? std::string_view("error") : error, kMaxReasonBytes));
  return finish(fbb, wire::CreateReadBoxResult(fbb, request_id, &mn, &mx, 0, e));
}

Frame build_presence(std::span<const PresenceEntryMsg> entries) {
  FlatBufferBuilder fbb(64 + entries.size() * 32);
  std::vector<flatbuffers::Offset<wire::PresenceEntry>> out;
  out.reserve(std::min(entries.size(), kMaxPresenceEntries));
  for (std::size_t i = 0; i < entries.size() && i < kMaxPresenceEntries; ++i) {
    const auto p = to_wire(entries[i].position);
    const auto name = entries[i].name.empty() ? 0 : fbb.CreateString(entries[i].name);
    out.push_back(wire::CreatePresenceEntry(fbb, entries[i].client_id, &p, name));
  }
  return finish(fbb, wire::CreatePresenceDirect(fbb, &out));
}

Frame build_presence_records(std::span<const std::uint8_t> records) {
  FlatBufferBuilder fbb(records.size() + 64);
  const auto r = fbb.CreateVector(records.data(), records.size());
  return finish(fbb, wire::CreatePresenceRecords(fbb, r));
}

Frame build_stream_batch(std::span<const std::uint8_t> records) {
  FlatBufferBuilder fbb(records.size() + 64);
  const auto r = fbb.CreateVector(records.data(), records.size());
  return finish(fbb, wire::CreateStreamBatch(fbb, r));
}

OutFrame gather_stream_batch(OutFrame records) {
  FlatBufferBuilder fbb(records.size() + 64);
  std::uint8_t* unused = nullptr;
  const auto r = fbb.CreateUninitializedVector(records.size(), &unused);
  return finish_around(fbb, wire::CreateStreamBatch(fbb, r), r.o, std::move(records));
}

std::vector<Frame> build_region_holdings(std::span<const HeldChunkMsg> claims, std::uint64_t world_id) {
  // Whole regions to a message, at most kMaxHoldingsPerMessage claims each.
  std::vector<HeldChunkMsg> sorted(claims.begin(), claims.end());
  const auto key = [](const HeldChunkMsg& c) {
    const Vec3i r = coarse_region_of(c.chunk_pos);
    return std::tuple(r.y, r.z, r.x);
  };
  std::stable_sort(sorted.begin(), sorted.end(), [&](const auto& a, const auto& b) { return key(a) < key(b); });
  std::vector<Frame> frames;
  std::vector<std::uint8_t> bytes;
  for (std::size_t i = 0; i < sorted.size();) {
    std::size_t end = i;
    while (end < sorted.size()) {
      std::size_t next = end;
      while (next < sorted.size() && key(sorted[next]) == key(sorted[end])) ++next;
      // A region has at most 512 claims (more only with duplicates): at
      // least one region a message, so the loop always advances.
      if (next - i > kMaxHoldingsPerMessage && end > i) break;
      end = next;
    }
    bytes.clear();
    encode_region_claims(std::span<const HeldChunkMsg>(sorted).subspan(i, end - i), bytes);
    FlatBufferBuilder fbb(64 + bytes.size());
    const auto vec = fbb.CreateVector(bytes);
    wire::HoldingsBuilder b(fbb);
    b.add_regions(vec);
    if (world_id != 0) b.add_world_id(world_id);
    frames.push_back(finish(fbb, b.Finish()));
    i = end;
  }
  return frames;
}

Frame build_holdings(std::span<const HeldChunkMsg> chunks) {
  const std::size_t n = std::min(chunks.size(), kMaxHoldingsPerMessage);
  std::vector<wire::HeldChunk> v;
  v.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    v.emplace_back(to_wire(chunks[i].chunk_pos), chunks[i].holding.revision,
                   static_cast<std::uint8_t>(chunks[i].holding.form));
  FlatBufferBuilder fbb(64 + n * sizeof(wire::HeldChunk));
  const auto vec = fbb.CreateVectorOfStructs(v);
  return finish(fbb, wire::CreateHoldings(fbb, vec));
}

Frame build_chunk_hash(const ChunkHashMsg& m) {
  FlatBufferBuilder fbb(64);
  const auto p = to_wire(m.chunk_pos);
  return finish(fbb, wire::CreateChunkHash(fbb, &p, m.revision, m.hash));
}

Frame build_chunk_hash_request(Vec3i chunk_pos) {
  FlatBufferBuilder fbb(64);
  const auto p = to_wire(chunk_pos);
  return finish(fbb, wire::CreateChunkHashRequest(fbb, &p));
}

Frame build_ping(std::uint64_t nonce) {
  FlatBufferBuilder fbb(32);
  return finish(fbb, wire::CreatePing(fbb, nonce));
}

Frame build_pong(std::uint64_t nonce) {
  FlatBufferBuilder fbb(32);
  return finish(fbb, wire::CreatePong(fbb, nonce));
}

// --- parsers -------------------------------------------------------------------

Result<HelloMsg> parse_hello(const wire::Hello& m) {
  HelloMsg out;
  out.protocol_version = m.protocol_version();
  if (m.client_name() == nullptr || m.client_name()->size() == 0) return invalid("hello: missing client name");
  if (m.client_name()->size() > kMaxClientNameBytes) return over("hello: client name longer than 64 bytes");
  if (has_control_character(m.client_name()->string_view()))
    return invalid("hello: client name has a control character (names must be printable)");
  if (m.auth_token() != nullptr && m.auth_token()->size() > kMaxAuthTokenBytes)
    return over("hello: auth token longer than 256 bytes");
  if (m.resume_token() != nullptr) {
    if (m.resume_token()->size() > kMaxResumeTokenBytes) return over("hello: resume token longer than 64 bytes");
    if (has_control_character(m.resume_token()->string_view()))
      return invalid("hello: resume token has a control character");
  }
  out.client_name = m.client_name()->str();
  if (m.auth_token() != nullptr) out.auth_token = m.auth_token()->str();
  if (m.resume_token() != nullptr) out.resume_token = m.resume_token()->str();
  out.features = m.features();
  return out;
}

Result<WelcomeMsg> parse_welcome(const wire::Welcome& m) {
  WelcomeMsg out;
  out.protocol_version = m.protocol_version();
  out.server_epoch = m.server_epoch();
  out.world_id = m.world_id();
  if (m.spawn() == nullptr) return invalid("welcome: missing spawn");
  out.spawn = from_wire(*m.spawn());
  if (!position_ok(out.spawn)) return invalid("welcome: spawn out of range");
  if (m.materials() != nullptr) {
    if (m.materials()->size() > kMaxMaterialNames) return over("welcome: more than 64 materials");
    for (const auto* s : *m.materials()) out.materials.push_back(s == nullptr ? std::string() : s->str());
  }
  out.bounds_min_y = m.bounds_min_y();
  out.bounds_max_y = m.bounds_max_y();
  if (out.bounds_min_y >= out.bounds_max_y) return invalid("welcome: empty vertical bounds");
  out.max_view_distance = m.max_view_distance();
  out.max_full_res_radius = m.max_full_res_radius();
  if (out.max_view_distance < 0 || out.max_full_res_radius < 0) return invalid("welcome: negative radius");
  out.max_frame_bytes = m.max_frame_bytes();
  if (out.max_frame_bytes < 1024 || out.max_frame_bytes > kDefaultMaxFrameBytes)
    return invalid("welcome: max frame size out of range");
  out.tick_hz = m.tick_hz();
  if (out.tick_hz == 0 || out.tick_hz > 1000) return invalid("welcome: tick rate out of range");
  out.bounded_xz = m.bounded_xz();
  if (out.bounded_xz) {
    out.bounds_min_x = m.bounds_min_x();
    out.bounds_min_z = m.bounds_min_z();
    out.bounds_max_x = m.bounds_max_x();
    out.bounds_max_z = m.bounds_max_z();
    if (!out.bounds().validate().empty()) return invalid("welcome: bad horizontal bounds");
  }
  out.default_view_distance = m.default_view_distance();
  out.default_full_res_radius = m.default_full_res_radius();
  if (out.default_view_distance < 0 || out.default_full_res_radius < 0 ||
      out.default_view_distance > out.max_view_distance || out.default_full_res_radius > out.max_full_res_radius)
    return invalid("welcome: defaults beyond the caps");
  out.edits_per_second = m.edits_per_second();
  out.edit_burst = m.edit_burst();
  out.server_id = m.server_id();
  if (!(out.edits_per_second >= 0) || out.edits_per_second > 1e6) return invalid("welcome: edit rate out of range");
  return out;
}

Result<std::string> parse_disconnect(const wire::Disconnect& m) {
  if (m.reason() == nullptr) return std::string();
  if (m.reason()->size() > kMaxReasonBytes) return over("disconnect: reason longer than 256 bytes");
  return m.reason()->str();
}

Result<AdminRequestMsg> parse_admin_request(const wire::AdminRequest& m) {
  AdminRequestMsg out;
  out.request_id = m.request_id();
  if (m.command() == nullptr || m.command()->size() == 0) return invalid("admin request: missing command");
  if (m.command()->size() > kMaxAdminCommandBytes) return over("admin request: command longer than 32 bytes");
  out.command = m.command()->str();
  if (m.args() != nullptr) {
    if (m.args()->size() > kMaxAdminArgs) return over("admin request: more than 16 arguments");
    for (const auto* a : *m.args()) {
      if (a == nullptr) return invalid("admin request: missing argument");
      if (a->size() > kMaxAdminArgBytes) return over("admin request: argument longer than 1024 bytes");
      out.args.push_back(a->str());
    }
  }
  return out;
}

Result<AdminResultMsg> parse_admin_result(const wire::AdminResult& m) {
  AdminResultMsg out;
  out.request_id = m.request_id();
  out.ok = m.ok();
  if (m.text() != nullptr) out.text = m.text()->str();
  if (m.json() != nullptr) out.json = m.json()->str();
  return out;
}

Result<ServerNoticeMsg> parse_server_notice(const wire::ServerNotice& m) {
  ServerNoticeMsg out;
  out.kind = m.kind();  // kinds this side does not know are kept (and ignored by the client)
  if (m.text() != nullptr) {
    if (m.text()->size() > kMaxNoticeBytes) return over("server notice: text longer than 1024 bytes");
    out.text = m.text()->str();
  }
  out.seconds_left = m.seconds_left();
  out.reconnect = m.reconnect();
  return out;
}

Result<RedirectMsg> parse_redirect(const wire::Redirect& m) {
  RedirectMsg out;
  out.server_id = m.server_id();
  if (m.host() == nullptr || m.host()->size() == 0) return invalid("redirect: missing host");
  if (m.host()->size() > kMaxRedirectHostBytes) return over("redirect: host longer than 253 bytes");
  out.host = m.host()->str();
  // A host name or an address: no spaces, controls or NULs (it is resolved).
  for (const char ch : out.host)
    if (static_cast<unsigned char>(ch) <= 0x20 || ch == 0x7f) return invalid("redirect: host has a control or space");
  out.port = m.port();
  if (out.port == 0) return invalid("redirect: port 0");
  if (m.token() != nullptr) {
    if (m.token()->size() > kMaxResumeTokenBytes) return over("redirect: token longer than 64 bytes");
    out.token = m.token()->str();
  }
  return out;
}

Result<ClientStateMsg> parse_client_state(const wire::ClientState& m) {
  ClientStateMsg out;
  if (m.position() == nullptr) return invalid("client state: missing position");
  out.position = from_wire(*m.position());
  if (!position_ok(out.position)) return invalid("client state: position out of range");
  out.view_distance = m.view_distance();
  out.full_res_radius = m.full_res_radius();
  if (out.view_distance < 0 || out.view_distance > kMaxWireViewDistance) return invalid("client state: view distance");
  if (out.full_res_radius < 0 || out.full_res_radius > kMaxWireViewDistance)
    return invalid("client state: full-resolution radius");
  return out;
}

namespace {

Result<Region> parse_box(const wire::Vec3i* mn, const wire::Vec3i* mx, std::int64_t max_volume, const char* what) {
  if (mn == nullptr || mx == nullptr) return invalid(what);
  const Region box{from_wire(*mn), from_wire(*mx)};
  if (!wire_coordinate_ok(box.min) || !wire_coordinate_ok(box.max)) return invalid(what);
  if (box.empty()) return invalid(what);
  if (box.volume() > max_volume) return over(what);
  return box;
}

// Decodes byte RLE voxels of box (volume already bounded by the caller).
Status decode_raw_box(const Region& box, const flatbuffers::Vector<std::uint8_t>* data, std::vector<Voxel>& out) {
  out.assign(static_cast<std::size_t>(box.volume()), Voxel{});
  return byte_rle_decode(bytes_of(data), out);
}

}  // namespace

Result<EditRequestMsg> parse_edit_request(const wire::EditRequest& m) {
  EditRequestMsg out;
  out.edit_id = m.edit_id();
  out.material = m.material();
  out.occupancy = m.occupancy();
  if (out.material >= kMaterialCount) return invalid("edit: material id >= 64");
  const bool has_data = m.data() != nullptr && m.data()->size() != 0;
  switch (m.kind()) {
    case wire::EditKind::FillBox: {
      out.kind = EditKind::kFillBox;
      auto box = parse_box(m.min(), m.max(), kMaxEditVolume, "edit: box missing, out of range, empty or over 64^3");
      if (!box) return box.error();
      out.box = *box;
      if (out.material == kAir) out.occupancy = 0;
      if (has_data) return invalid("edit: unexpected data");
      return out;
    }
    case wire::EditKind::WriteBox: {
      out.kind = EditKind::kWriteBox;
      auto box =
          parse_box(m.min(), m.max(), kMaxRawBoxVolume, "edit: write box missing, out of range, empty or over 32^3");
      if (!box) return box.error();
      out.box = *box;
      if (auto st = decode_raw_box(out.box, m.data(), out.voxels); !st)
        return DecodeError{st.error().code, st.error().offset, "edit: write box data is not byte RLE of its box"};
      return out;
    }
    case wire::EditKind::Undo:
    case wire::EditKind::Redo:
      out.kind = m.kind() == wire::EditKind::Undo ? EditKind::kUndo : EditKind::kRedo;
      if (has_data) return invalid("edit: unexpected data");
      return out;
    case wire::EditKind::FillSphere:
    case wire::EditKind::Dig:
    case wire::EditKind::Paint:
    case wire::EditKind::Smooth:
      break;
    default:
      return invalid("edit: unknown kind");
  }
  out.kind = static_cast<EditKind>(m.kind());
  if (m.center() == nullptr) return invalid("edit: sphere without centre");
  out.center = from_wire(*m.center());
  out.radius = m.radius();
  if (!position_ok(out.center)) return invalid("edit: sphere centre out of range");
  if (!std::isfinite(out.radius) || out.radius <= 0.0f) return invalid("edit: sphere radius not positive");
  if (out.radius > kMaxSphereRadius) return over("edit: sphere radius above 32");
  if (has_data) return invalid("edit: unexpected data");
  if (out.kind == EditKind::kDig) out.material = kAir;
  if (out.kind == EditKind::kPaint && out.material == kAir) return invalid("edit: paint with Air");
  if (out.kind == EditKind::kSmooth && out.occupancy == 0) out.occupancy = 128;
  return out;
}

Result<UpdateBatchMsg> parse_update_batch(const wire::UpdateBatch& m) {
  UpdateBatchMsg out;
  out.tick = m.tick();
  out.data = bytes_of(m.data());
  if (out.data.empty()) return invalid("update batch: no data");
  if (m.revisions() == nullptr || m.revisions()->size() == 0) return invalid("update batch: no revisions");
  if (m.revisions()->size() > kMaxBatchRevisions) return over("update batch: too many revisions");
  // Read the 24-byte structs as bytes: FrameReader hands out aligned bodies,
  // but a caller may pass any span (tests, fuzzers), and a ChunkRevision*
  // into a misaligned buffer must not be dereferenced.
  static_assert(sizeof(wire::ChunkRevision) == 24);
  const std::uint8_t* raw = m.revisions()->Data();
  out.revisions.reserve(m.revisions()->size());
  for (flatbuffers::uoffset_t i = 0; i < m.revisions()->size(); ++i) {
    const ChunkRevisionMsg cr = read_chunk_and_revision(raw + std::size_t{i} * sizeof(wire::ChunkRevision));
    if (!wire_chunk_ok(cr.chunk_pos)) return invalid("update batch: chunk position out of range");
    out.revisions.push_back(cr);
  }
  return out;
}

Result<ChunkHashMsg> parse_chunk_hash(const wire::ChunkHash& m) {
  ChunkHashMsg out;
  if (m.chunk_pos() == nullptr) return invalid("chunk hash: missing chunk position");
  out.chunk_pos = from_wire(*m.chunk_pos());
  if (!wire_chunk_ok(out.chunk_pos)) return invalid("chunk hash: chunk position out of range");
  out.revision = m.revision();
  out.hash = m.hash();
  return out;
}

Result<Vec3i> parse_chunk_hash_request(const wire::ChunkHashRequest& m) {
  if (m.chunk_pos() == nullptr) return invalid("chunk hash request: missing chunk position");
  const Vec3i p = from_wire(*m.chunk_pos());
  if (!wire_chunk_ok(p)) return invalid("chunk hash request: chunk position out of range");
  return p;
}

Result<ReadBoxMsg> parse_read_box(const wire::ReadBox& m) {
  ReadBoxMsg out;
  out.request_id = m.request_id();
  auto box = parse_box(m.min(), m.max(), kMaxRawBoxVolume, "read box: box missing, out of range, empty or over 32^3");
  if (!box) return box.error();
  out.box = *box;
  return out;
}

Result<ReadBoxResultMsg> parse_read_box_result(const wire::ReadBoxResult& m) {
  ReadBoxResultMsg out;
  out.request_id = m.request_id();
  auto box =
      parse_box(m.min(), m.max(), kMaxRawBoxVolume, "read box result: box missing, out of range, empty or over 32^3");
  if (!box) return box.error();
  out.box = *box;
  if (m.error() != nullptr && m.error()->size() != 0) {
    if (m.error()->size() > kMaxReasonBytes) return over("read box result: error longer than 256 bytes");
    out.error = m.error()->str();
    return out;
  }
  if (auto st = decode_raw_box(out.box, m.data(), out.voxels); !st)
    return DecodeError{st.error().code, st.error().offset, "read box result: data is not byte RLE of its box"};
  return out;
}

Result<EditRejectMsg> parse_edit_reject(const wire::EditReject& m) {
  EditRejectMsg out;
  out.edit_id = m.edit_id();
  out.outcome_unknown = m.outcome_unknown();
  if (m.reason() != nullptr) {
    if (m.reason()->size() > kMaxReasonBytes) return over("edit reject: reason longer than 256 bytes");
    out.reason = m.reason()->str();
  }
  if (m.data() == nullptr) return out;
  auto box = parse_box(m.min(), m.max(), kMaxEditVolume, "edit reject: box missing, out of range, empty or over 64^3");
  if (!box) return box.error();
  out.box = *box;
  if (auto st = decode_raw_box(out.box, m.data(), out.voxels); !st)
    return DecodeError{st.error().code, st.error().offset, "edit reject: data is not byte RLE of its box"};
  return out;
}

Result<std::vector<PresenceEntryMsg>> parse_presence(const wire::Presence& m) {
  std::vector<PresenceEntryMsg> out;
  if (m.entries() == nullptr) return out;
  if (m.entries()->size() > kMaxPresenceEntries) return over("presence: more than 64 entries");
  for (const auto* e : *m.entries()) {
    if (e == nullptr || e->position() == nullptr) return invalid("presence: entry without position");
    PresenceEntryMsg p{e->client_id(), from_wire(*e->position()), {}};
    if (!position_ok(p.position)) return invalid("presence: position out of range");
    if (e->name() != nullptr) {
      // A client name as Hello allows it (clients show and log it).
      if (e->name()->size() > kMaxClientNameBytes || has_control_character(e->name()->string_view()))
        return invalid("presence: name longer than 64 bytes or with a control character");
      p.name = e->name()->str();
    }
    out.push_back(p);
  }
  return out;
}

std::span<const std::uint8_t> parse_presence_records(const wire::PresenceRecords& m) { return bytes_of(m.records()); }

Result<std::span<const std::uint8_t>> parse_stream_batch(const wire::StreamBatch& m) {
  const auto records = bytes_of(m.records());
  if (records.empty()) return invalid("stream batch: no records");
  return records;
}

namespace {

Result<std::vector<HeldChunkMsg>> parse_held_chunks(const flatbuffers::Vector<const wire::HeldChunk*>& chunks) {
  std::vector<HeldChunkMsg> out;
  if (chunks.size() > kMaxHoldingsPerMessage) return over("holdings: more than 16384 chunks");
  // Bytewise, like UpdateBatch revisions (see there).
  static_assert(sizeof(wire::HeldChunk) == 32);
  const std::uint8_t* raw = chunks.Data();
  out.reserve(chunks.size());
  for (flatbuffers::uoffset_t i = 0; i < chunks.size(); ++i) {
    const std::uint8_t* e = raw + std::size_t{i} * sizeof(wire::HeldChunk);
    const ChunkRevisionMsg cr = read_chunk_and_revision(e);
    if (!wire_chunk_ok(cr.chunk_pos)) return invalid("holdings: chunk position out of range");
    if (e[24] >= kHoldingForms || !claimable(static_cast<HoldingForm>(e[24])))
      return invalid("holdings: form not 0..4 (Full, Mip 1..3, Empty)");
    HeldChunkMsg h{cr.chunk_pos, Holding{static_cast<HoldingForm>(e[24]), cr.revision}};
    out.push_back(h);
  }
  return out;
}

}  // namespace

Result<std::vector<HeldChunkMsg>> parse_holdings(const wire::Holdings& m) {
  std::vector<HeldChunkMsg> out;
  if (m.chunks() != nullptr) {
    auto chunks = parse_held_chunks(*m.chunks());
    if (!chunks) return chunks.error();
    out = std::move(*chunks);
  }
  if (m.regions() != nullptr) {
    // At most kMaxHoldingsPerMessage claims in all, the chunks' counted.
    if (auto s = decode_region_claims(bytes_of(m.regions()), out, kMaxHoldingsPerMessage); !s) return s.error();
  }
  return out;
}

// --- chunk hash ------------------------------------------------------------------

std::uint64_t chunk_hash(const Chunk* chunk, std::uint64_t revision) { return chunk_hash_of(chunk, revision); }

}  // namespace terrane
