// The place database byte format (formats/place_db.md): header, chunks with CRCs,
// every length checked against the bytes left and a cap before allocating.

#include <zlib.h>

#include <cmath>
#include <cctype>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "lex3d/codec/codec.hpp"
#include "lex3d/place/place.hpp"
#include "place/internal.hpp"

namespace lex3d {

namespace {

constexpr char kMagic[8] = {'L', 'E', 'X', '3', 'D', 'P', 'D', 'B'};
constexpr std::uint16_t kMajor = 2;  // written; 1.0 is read too
constexpr std::uint16_t kMinor = 1;  // 2.1: the recognition vocabulary (VOCB, VIDX)
constexpr std::size_t kSlotBytes = 28;
constexpr std::size_t kSlotsEnd = 20 + 2 * kSlotBytes;  // first chunk of a 2.x file
constexpr std::size_t kEntryBytes = 36;
constexpr std::uint32_t kMaxWordSlots = 1u << 24;
constexpr std::size_t kHeaderBytes = 20;
constexpr std::size_t kPhdrBytes = 32;
constexpr std::uint32_t kMaxScans = 1u << 24;
constexpr std::uint32_t kMaxName = 4096;
constexpr std::uint32_t kMaxFeatures = 4096;
constexpr std::uint32_t kMaxDim = 4096;
constexpr std::uint64_t kMaxPixels = 1u << 22;

class Writer {
 public:
  std::vector<std::uint8_t> b;
  void u8(std::uint8_t v) { b.push_back(v); }
  void u16(std::uint16_t v) {
    for (int i = 0; i < 2; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void u32(std::uint32_t v) {
    for (int i = 0; i < 4; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void u64(std::uint64_t v) {
    for (int i = 0; i < 8; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void i16(std::int16_t v) { u16(static_cast<std::uint16_t>(v)); }
  void f32(float f) {
    std::uint32_t v = 0;
    std::memcpy(&v, &f, 4);
    u32(v);
  }
  void f64(double d) {
    std::uint64_t v = 0;
    std::memcpy(&v, &d, 8);
    u64(v);
  }
  void bytes(const std::uint8_t* p, std::size_t n) { b.insert(b.end(), p, p + n); }
  void pose(const Pose& T) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) f64(T.matrix()(r, c));
  }
};

class Reader {
 public:
  Reader(const std::uint8_t* p, std::size_t n, std::uint64_t base) : p_(p), n_(n), base_(base) {}
  [[nodiscard]] std::size_t left() const { return n_ - pos_; }
  [[nodiscard]] std::uint64_t offset() const { return base_ + pos_; }
  bool u8(std::uint8_t& v) {
    if (left() < 1) return false;
    v = p_[pos_++];
    return true;
  }
  bool u16(std::uint16_t& v) {
    std::uint64_t x = 0;
    if (!le(2, x)) return false;
    v = static_cast<std::uint16_t>(x);
    return true;
  }
  bool u32(std::uint32_t& v) {
    std::uint64_t x = 0;
    if (!le(4, x)) return false;
    v = static_cast<std::uint32_t>(x);
    return true;
  }
  bool u64(std::uint64_t& v) { return le(8, v); }
  bool i16(std::int16_t& v) {
    std::uint16_t u = 0;
    if (!u16(u)) return false;
    v = static_cast<std::int16_t>(u);
    return true;
  }
  bool f32(float& f) {
    std::uint32_t v = 0;
    if (!u32(v)) return false;
    std::memcpy(&f, &v, 4);
    return true;
  }
  bool f64(double& d) {
    std::uint64_t v = 0;
    if (!u64(v)) return false;
    std::memcpy(&d, &v, 8);
    return true;
  }
  const std::uint8_t* take(std::size_t n) {
    if (left() < n) return nullptr;
    const std::uint8_t* q = p_ + pos_;
    pos_ += n;
    return q;
  }
  bool pose(Pose& T) {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c)
        if (!f64(m(r, c))) return false;
    if (!m.allFinite()) return false;
    const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
    if ((R * R.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-3 || R.determinant() < 0) return false;
    T.matrix() = m;
    return true;
  }

 private:
  bool le(int bytes, std::uint64_t& v) {
    if (left() < static_cast<std::size_t>(bytes)) return false;
    v = 0;
    for (int i = 0; i < bytes; ++i) v |= static_cast<std::uint64_t>(p_[pos_ + static_cast<std::size_t>(i)]) << (8 * i);
    pos_ += static_cast<std::size_t>(bytes);
    return true;
  }
  const std::uint8_t* p_;
  std::size_t n_;
  std::uint64_t base_;
  std::size_t pos_ = 0;
};

std::uint32_t crc(const std::uint8_t* p, std::size_t n) {
  uLong c = crc32(0L, Z_NULL, 0);
  while (n > 0) {
    const auto step = static_cast<uInt>(std::min<std::size_t>(n, 1u << 30));
    c = crc32(c, p, step);
    p += step;
    n -= step;
  }
  return static_cast<std::uint32_t>(c);
}

void put_chunk(std::vector<std::uint8_t>& out, const char type[4], const std::vector<std::uint8_t>& payload) {
  const std::size_t start = out.size();
  Writer w;
  w.bytes(reinterpret_cast<const std::uint8_t*>(type), 4);
  w.u64(payload.size());
  out.insert(out.end(), w.b.begin(), w.b.end());
  out.insert(out.end(), payload.begin(), payload.end());
  const std::uint32_t c = crc(out.data() + start, out.size() - start);
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(c >> (8 * i)));
}

constexpr std::uint16_t kUnobservedCode = 0;
constexpr std::uint16_t kMaxRangeCode = 65535;

}  // namespace

namespace detail {

std::vector<std::uint8_t> encode_scan_payload(const PlaceScan& s, double range_step) {
  Writer w;
  const std::string name = s.name.substr(0, kMaxName);
  w.u16(static_cast<std::uint16_t>(name.size()));
  w.bytes(reinterpret_cast<const std::uint8_t*>(name.data()), name.size());
  w.u8(s.has_world_pose ? 1 : 0);
  w.pose(s.T_world_cloud);
  w.pose(s.coarse.T_cloud_sensor);
  w.u32(static_cast<std::uint32_t>(s.words.size()));
  for (const auto& [word, count] : s.words) {
    w.u32(word);
    w.u32(count);
  }
  w.u32(static_cast<std::uint32_t>(s.features.size()));
  for (const auto& f : s.features) {
    w.f32(f.position.x());
    w.f32(f.position.y());
    w.f32(f.position.z());
    for (const auto v : quantise_rotation(f.rotation)) w.i16(v);
  }
  // Descriptor codes, packed: 8 bits one a byte; 4 bits two a byte, low nibble first.
  if (s.descriptor_bits == 8) {
    w.bytes(s.descriptor_codes.data(), s.descriptor_codes.size());
  } else {
    for (std::size_t i = 0; i < s.descriptor_codes.size(); i += 2) {
      const std::uint8_t lo = s.descriptor_codes[i] & 0x0F;
      const std::uint8_t hi = i + 1 < s.descriptor_codes.size() ? (s.descriptor_codes[i + 1] & 0x0F) : 0;
      w.u8(static_cast<std::uint8_t>(lo | (hi << 4)));
    }
  }
  // Coarse range image.
  const RangeImage& c = s.coarse;
  w.u16(static_cast<std::uint16_t>(c.width));
  w.u16(static_cast<std::uint16_t>(c.height));
  w.u8(c.full_circle ? 1 : 0);
  w.f64(c.azimuth_resolution_rad);
  w.f64(c.azimuth_max_rad);
  w.f64(c.elevation_resolution_rad);
  for (const double e : c.row_edges) w.f64(e);
  const std::size_t pixels = static_cast<std::size_t>(c.width) * static_cast<std::size_t>(c.height);
  std::vector<std::uint8_t> raw(2 * pixels);
  for (int y = 0; y < c.height; ++y) {
    std::uint16_t prev = 0;
    for (int x = 0; x < c.width; ++x) {
      const std::size_t i = c.index(x, y);
      const std::uint16_t code = c.state[i] == PixelState::kValid      ? quantise_range(c.range[i], range_step)
                                 : c.state[i] == PixelState::kMaxRange ? kMaxRangeCode
                                                                       : kUnobservedCode;
      const auto delta = static_cast<std::uint16_t>(code - prev);
      prev = code;
      raw[i] = static_cast<std::uint8_t>(delta & 0xFF);
      raw[pixels + i] = static_cast<std::uint8_t>(delta >> 8);
    }
  }
  std::vector<std::uint8_t> z;
  if (pixels > 0) {
    uLongf zlen = compressBound(static_cast<uLong>(raw.size()));
    z.resize(zlen);
    if (compress2(z.data(), &zlen, raw.data(), static_cast<uLong>(raw.size()), 9) != Z_OK)
      throw std::runtime_error("lex3d::place: zlib compress2 failed");
    z.resize(zlen);
  }
  w.u32(static_cast<std::uint32_t>(z.size()));
  w.bytes(z.data(), z.size());
  return std::move(w.b);
}

}  // namespace detail

namespace {

struct DbHeader {
  std::uint32_t scan_count = 0;
  std::uint16_t descriptor_dim = 0;
  std::uint8_t descriptor_bits = 8;
  PlaceStorageParams storage;
};

StatusOr<PlaceScan> decode_scan(const std::uint8_t* p, std::size_t n, std::uint64_t base, const DbHeader& h,
                                std::size_t alphabet_words, bool has_alphabet) {
  Reader r(p, n, base);
  auto trunc = [&](const char* what) { return bad_data(std::string("place database: SCAN chunk truncated in ") + what, r.offset()); };
  PlaceScan s;
  std::uint16_t name_len = 0;
  if (!r.u16(name_len)) return trunc("the name");
  if (name_len > kMaxName) return bad_data("place database: scan name too long", r.offset() - 2);
  const std::uint8_t* nm = r.take(name_len);
  if (nm == nullptr) return trunc("the name");
  s.name.assign(reinterpret_cast<const char*>(nm), name_len);
  std::uint8_t flags = 0;
  if (!r.u8(flags)) return trunc("the flags");
  if ((flags & ~1u) != 0) return bad_data("place database: reserved scan flag set", r.offset() - 1);
  s.has_world_pose = (flags & 1u) != 0;
  const std::uint64_t pose_at = r.offset();
  if (r.left() < 192) return trunc("the poses");
  if (!r.pose(s.T_world_cloud)) return bad_data("place database: T_world_cloud is not a rigid transform", pose_at);
  if (!r.pose(s.coarse.T_cloud_sensor)) return bad_data("place database: T_cloud_sensor is not a rigid transform", pose_at + 96);
  std::uint32_t nw = 0;
  if (!r.u32(nw)) return trunc("the word count");
  if (static_cast<std::uint64_t>(nw) * 8 > r.left())
    return bad_data("place database: word count " + std::to_string(nw) + " does not fit the chunk", r.offset() - 4);
  s.words.reserve(nw);
  for (std::uint32_t i = 0; i < nw; ++i) {
    std::uint32_t word = 0, count = 0;
    r.u32(word);
    r.u32(count);
    if ((i > 0 && word <= s.words.back().first) || count == 0 || (has_alphabet && word >= alphabet_words))
      return bad_data("place database: bad word entry (unsorted, zero count or unknown word)", r.offset() - 8);
    s.words.emplace_back(word, count);
  }
  std::uint32_t nf = 0;
  if (!r.u32(nf)) return trunc("the feature count");
  if (nf > kMaxFeatures) return bad_data("place database: feature count " + std::to_string(nf) + " too large", r.offset() - 4);
  const std::uint64_t codes = static_cast<std::uint64_t>(nf) * h.descriptor_dim;
  const std::uint64_t code_bytes = h.descriptor_bits == 8 ? codes : (codes + 1) / 2;
  if (static_cast<std::uint64_t>(nf) * 20 + code_bytes > r.left())
    return bad_data("place database: " + std::to_string(nf) + " features do not fit the chunk", r.offset() - 4);
  s.features.resize(nf);
  for (auto& f : s.features) {
    float x = 0, y = 0, z = 0;
    r.f32(x);
    r.f32(y);
    r.f32(z);
    f.position = {x, y, z};
    std::array<std::int16_t, 4> q{};
    for (auto& v : q) r.i16(v);
    if (!f.position.allFinite() || (q[0] == 0 && q[1] == 0 && q[2] == 0 && q[3] == 0))
      return bad_data("place database: feature frame is not finite or has a zero rotation", r.offset() - 20);
    f.rotation = detail::dequantise_rotation(q);
  }
  s.descriptor = h.storage.descriptor;
  s.descriptor_dim = h.descriptor_dim;
  s.descriptor_bits = h.descriptor_bits;
  const std::uint8_t* cb = r.take(static_cast<std::size_t>(code_bytes));
  s.descriptor_codes.resize(static_cast<std::size_t>(codes));
  if (h.descriptor_bits == 8) {
    if (codes > 0) std::memcpy(s.descriptor_codes.data(), cb, static_cast<std::size_t>(codes));
  } else {
    for (std::size_t i = 0; i < codes; ++i)
      s.descriptor_codes[i] = static_cast<std::uint8_t>((cb[i / 2] >> (4 * (i % 2))) & 0x0F);
  }
  // Coarse range image.
  RangeImage& c = s.coarse;
  std::uint16_t w16 = 0, h16 = 0;
  std::uint8_t full = 0;
  const std::uint64_t img_at = r.offset();
  if (!r.u16(w16) || !r.u16(h16) || !r.u8(full) || !r.f64(c.azimuth_resolution_rad) || !r.f64(c.azimuth_max_rad) ||
      !r.f64(c.elevation_resolution_rad))
    return trunc("the coarse image header");
  const std::uint64_t pixels = static_cast<std::uint64_t>(w16) * h16;
  if (full > 1 || pixels > kMaxPixels || ((w16 == 0) != (h16 == 0)) ||
      (pixels > 0 && !(std::isfinite(c.azimuth_resolution_rad) && c.azimuth_resolution_rad > 0.0 &&
                       c.azimuth_resolution_rad <= 2 * M_PI && std::isfinite(c.azimuth_max_rad) &&
                       std::isfinite(c.elevation_resolution_rad) && c.elevation_resolution_rad > 0.0)))
    return bad_data("place database: invalid coarse image header", img_at);
  // The image spans at most one turn, and a turn (half a turn in elevation) at its resolution
  // fits the 16-bit width (height): projected pixel coordinates then stay small integers.
  if (pixels > 0 && (static_cast<double>(w16) * c.azimuth_resolution_rad > 2 * M_PI + c.azimuth_resolution_rad ||
                     2 * M_PI / c.azimuth_resolution_rad > 65535.0 || M_PI / c.elevation_resolution_rad > 65535.0))
    return bad_data("place database: the coarse image's azimuth or elevation resolution does not fit its size", img_at);
  c.width = w16;
  c.height = h16;
  c.full_circle = full == 1;
  const std::size_t edges = pixels > 0 ? static_cast<std::size_t>(h16) + 1 : 0;
  if (edges * 8 > r.left()) return trunc("the row edges");
  c.row_edges.resize(edges);
  for (std::size_t i = 0; i < edges; ++i) {
    r.f64(c.row_edges[i]);
    if (!std::isfinite(c.row_edges[i]) || (i > 0 && !(c.row_edges[i] < c.row_edges[i - 1])))
      return bad_data("place database: coarse image row edges are not finite and decreasing", r.offset() - 8);
  }
  std::uint32_t zlen = 0;
  if (!r.u32(zlen)) return trunc("the coarse image size");
  if (zlen > r.left()) return bad_data("place database: coarse image data does not fit the chunk", r.offset() - 4);
  if ((pixels == 0) != (zlen == 0)) return bad_data("place database: coarse image data size is inconsistent", r.offset() - 4);
  const std::uint8_t* zd = r.take(zlen);
  if (r.left() != 0) return bad_data("place database: SCAN chunk has trailing bytes", r.offset());
  if (pixels > 0) {
    std::vector<std::uint8_t> raw(static_cast<std::size_t>(2 * pixels));
    uLongf out_len = static_cast<uLongf>(raw.size());
    if (uncompress(raw.data(), &out_len, zd, zlen) != Z_OK || out_len != raw.size())
      return bad_data("place database: coarse image data does not inflate to its size", r.offset() - zlen);
    const auto np = static_cast<std::size_t>(pixels);
    c.state.assign(np, PixelState::kUnobserved);
    c.range.assign(np, std::numeric_limits<float>::quiet_NaN());
    for (int y = 0; y < c.height; ++y) {
      std::uint16_t prev = 0;
      for (int x = 0; x < c.width; ++x) {
        const std::size_t i = c.index(x, y);
        const auto delta = static_cast<std::uint16_t>(raw[i] | (raw[np + i] << 8));
        const auto code = static_cast<std::uint16_t>(prev + delta);
        prev = code;
        if (code == kMaxRangeCode) {
          c.state[i] = PixelState::kMaxRange;
        } else if (code != kUnobservedCode) {
          c.state[i] = PixelState::kValid;
          c.range[i] = detail::dequantise_range(code, h.storage.range_step);
          ++c.valid_count;
        }
      }
    }
  }
  detail::finish_place_scan(s);
  return s;
}

}  // namespace

std::size_t stored_bytes(const PlaceScan& scan) {
  // range_step only changes code values, not the framing; 0.02 m is representative.
  return 16 + detail::encode_scan_payload(scan, 0.02).size();
}

SharedBytes SharedBytes::copy_of(const std::vector<std::uint8_t>& bytes) {
  auto v = std::make_shared<const std::vector<std::uint8_t>>(bytes);
  SharedBytes b;
  b.data = v->data();
  b.size = v->size();
  b.owner = v;
  return b;
}

namespace {

using detail::ld32;
using detail::ld64;
std::uint16_t ld16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | p[1] << 8); }
using detail::ldf64;

std::vector<std::uint8_t> chunk_bytes(const char type[4], const std::vector<std::uint8_t>& payload) {
  std::vector<std::uint8_t> out;
  out.reserve(payload.size() + 16);
  put_chunk(out, type, payload);
  return out;
}

// A chunk at `pos` of the first `limit` bytes: its type letters, its length against the
// bytes left, its CRC.
struct ChunkView {
  std::string type;
  const std::uint8_t* payload = nullptr;
  std::size_t length = 0;
  std::uint64_t at = 0;  // offset of the chunk (its type)
};

StatusOr<ChunkView> read_chunk(const std::uint8_t* bytes, std::uint64_t limit, std::uint64_t pos) {
  if (pos > limit || limit - pos < 16) return bad_data("place database: truncated chunk", std::min(pos, limit));
  char type[5] = {0, 0, 0, 0, 0};
  std::memcpy(type, bytes + pos, 4);
  for (int i = 0; i < 4; ++i)
    if (!std::isalpha(static_cast<unsigned char>(type[i]))) return bad_data("place database: chunk type is not 4 letters", pos);
  const std::uint64_t len = ld64(bytes + pos + 4);
  if (len > limit - pos - 16)
    return bad_data("place database: chunk '" + std::string(type) + "' length " + std::to_string(len) + " exceeds the file",
                    pos + 4);
  const auto plen = static_cast<std::size_t>(len);
  if (crc(bytes + pos, 12 + plen) != ld32(bytes + pos + 12 + plen))
    return bad_data("place database: CRC mismatch in chunk '" + std::string(type) + "'", pos + 12 + plen);
  return ChunkView{type, bytes + pos + 12, plen, pos};
}

std::vector<std::uint8_t> phdr_payload(const PlaceStorageParams& st, int dim, bool has_alphabet, std::uint32_t count) {
  Writer p;
  p.u32(count);
  p.u16(static_cast<std::uint16_t>(dim));
  p.u8(static_cast<std::uint8_t>(st.descriptor_bits));
  p.u8(has_alphabet ? 1 : 0);
  p.u32(static_cast<std::uint32_t>(st.max_features));
  p.f64(st.coarse_azimuth_deg);
  p.u16(static_cast<std::uint16_t>(st.coarse_row_factor));
  p.u16(static_cast<std::uint16_t>(st.descriptor));  // descriptor_kind (0: patch, the earlier reserved 0)
  p.f64(st.range_step);
  return std::move(p.b);
}

struct Phdr {
  std::uint32_t scan_count = 0;
  std::uint16_t descriptor_dim = 0;
  bool has_alphabet = false;
  PlaceStorageParams storage;
};

StatusOr<Phdr> parse_phdr(const ChunkView& c) {
  if (c.type != "PHDR") return bad_data("place database: first chunk is '" + c.type + "', not PHDR", c.at);
  if (c.length != kPhdrBytes)
    return bad_data("place database: PHDR has " + std::to_string(c.length) + " bytes, not 32", c.at + 4);
  Reader r(c.payload, c.length, c.at + 12);
  Phdr h;
  std::uint8_t bits = 0, alph = 0;
  std::uint32_t maxf = 0;
  std::uint16_t rowf = 0, kind = 0;
  r.u32(h.scan_count);
  r.u16(h.descriptor_dim);
  r.u8(bits);
  r.u8(alph);
  r.u32(maxf);
  r.f64(h.storage.coarse_azimuth_deg);
  r.u16(rowf);
  r.u16(kind);
  r.f64(h.storage.range_step);
  h.storage.max_features = static_cast<int>(std::min<std::uint32_t>(maxf, 1u << 30));
  h.storage.descriptor_bits = bits;
  h.storage.coarse_row_factor = rowf;
  if (h.scan_count > kMaxScans || h.descriptor_dim > kMaxDim || alph > 1)
    return bad_data("place database: PHDR field out of range", c.at + 12);
  if (kind > 1)
    return bad_data("place database: unknown descriptor kind " + std::to_string(kind) + " in PHDR", c.at + 12 + 22);
  h.storage.descriptor = static_cast<PlaceDescriptor>(kind);
  if (h.storage.descriptor == PlaceDescriptor::kVdlsd && h.descriptor_dim != 0 &&
      h.descriptor_dim != detail::stored_descriptor_dim(h.storage, nullptr))
    return bad_data("place database: PHDR descriptor_dim " + std::to_string(h.descriptor_dim) + " is not VD-LSD's " +
                        std::to_string(detail::stored_descriptor_dim(h.storage, nullptr)),
                    c.at + 12 + 4);
  try {
    h.storage.validate();
  } catch (const std::invalid_argument& e) {
    return bad_data(std::string("place database: PHDR: ") + e.what(), c.at + 12);
  }
  h.has_alphabet = alph == 1;
  return h;
}

// Per scan the squared norm of its tf-idf vector over `inverted` (word -> (scan, count)), as
// retrieval computes it; `postings` gets the postings' count.
std::vector<double> tfidf_norm2(std::size_t n, const std::vector<std::uint32_t>& totals,
                                const std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>>& inverted,
                                std::uint64_t* postings) {
  std::vector<double> norm2(n, 0.0);
  *postings = 0;
  for (std::size_t w = 0; w < inverted.size(); ++w) {
    *postings += inverted[w].size();
    if (inverted[w].empty()) continue;
    const double idf = std::log(1.0 + static_cast<double>(n) / static_cast<double>(inverted[w].size()));
    for (const auto& [s, c] : inverted[w]) {
      const double v = static_cast<double>(c) / static_cast<double>(totals[s]) * idf;
      norm2[s] += v * v;
    }
  }
  return norm2;
}

// The PIDX payload (formats/place_db.md §3.4) of entries given as parallel arrays; the
// norms are computed here, as retrieval computes them.
std::vector<std::uint8_t> encode_index(const std::vector<std::uint64_t>& offsets, const std::vector<std::uint64_t>& lengths,
                                       const std::vector<std::string>& names, const std::vector<std::uint32_t>& totals,
                                       const std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>>& inverted) {
  const std::size_t n = names.size();
  std::uint64_t postings = 0;
  const std::vector<double> norm2 = tfidf_norm2(n, totals, inverted, &postings);
  std::uint64_t names_length = 0;
  for (const auto& s : names) names_length += s.size();
  Writer w;
  w.b.reserve(24 + n * kEntryBytes + names_length + 8 * (inverted.size() + 1) + 8 * postings);
  w.u32(static_cast<std::uint32_t>(n));
  w.u32(static_cast<std::uint32_t>(inverted.size()));
  w.u64(postings);
  w.u64(names_length);
  std::uint64_t name_at = 0;
  for (std::size_t i = 0; i < n; ++i) {
    w.u64(offsets[i]);
    w.u64(lengths[i]);
    w.u32(totals[i]);
    w.u32(static_cast<std::uint32_t>(name_at));
    w.u16(static_cast<std::uint16_t>(names[i].size()));
    w.u16(0);
    w.f64(norm2[i]);
    name_at += names[i].size();
  }
  for (const auto& s : names) w.bytes(reinterpret_cast<const std::uint8_t*>(s.data()), s.size());
  std::uint64_t start = 0;
  w.u64(0);
  for (const auto& list : inverted) {
    start += list.size();
    w.u64(start);
  }
  for (const auto& list : inverted)
    for (const auto& [s, c] : list) {
      w.u32(s);
      w.u32(c);
    }
  return std::move(w.b);
}

// The VIDX payload (formats/place_db.md §3.6): per scan its vocabulary word total and tf-idf
// norm, the postings of every vocabulary word, and the payload's own length last (a reader
// finds the chunk from the PIDX offset).
std::vector<std::uint8_t> encode_vindex(const std::vector<std::uint32_t>& totals, std::size_t word_slots,
                                        const std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>>& inverted) {
  const std::size_t n = totals.size();
  std::uint64_t postings = 0;
  const std::vector<double> norm2 = tfidf_norm2(n, totals, inverted, &postings);
  Writer w;
  w.b.reserve(24 + 12 * n + 8 * (word_slots + 1) + 8 * postings);
  w.u32(static_cast<std::uint32_t>(n));
  w.u32(static_cast<std::uint32_t>(word_slots));
  w.u64(postings);
  for (std::size_t i = 0; i < n; ++i) {
    w.u32(totals[i]);
    w.f64(norm2[i]);
  }
  std::uint64_t start = 0;
  w.u64(0);
  for (std::size_t k = 0; k < word_slots; ++k) {
    if (k < inverted.size()) start += inverted[k].size();
    w.u64(start);
  }
  for (const auto& list : inverted)
    for (const auto& [s, c] : list) {
      w.u32(s);
      w.u32(c);
    }
  w.u64(w.b.size() + 8);
  return std::move(w.b);
}

std::vector<std::uint8_t> commit_slot(std::uint64_t seq, std::uint64_t end, std::uint64_t index_offset) {
  Writer w;
  w.u64(seq);
  w.u64(end);
  w.u64(index_offset);
  w.u32(crc(w.b.data(), 24));
  return std::move(w.b);
}

std::uint64_t slot_offset(std::uint64_t seq) { return 20 + kSlotBytes * (seq % 2); }

}  // namespace

std::string PlaceDatabase::name(std::size_t i) const {
  if (i < index_.scans) {
    const std::uint8_t* e = index_.entries + i * kEntryBytes;
    return {reinterpret_cast<const char*>(index_.names + ld32(e + 20)), ld16(e + 24)};
  }
  return added_.at(i - index_.scans).name;
}

std::uint32_t PlaceDatabase::word_total(std::size_t i) const {
  return i < index_.scans ? ld32(index_.entries + i * kEntryBytes + 16) : added_total_[i - index_.scans];
}

std::size_t PlaceDatabase::stored_postings(std::uint32_t word) const {
  if (word >= index_.word_slots) return 0;
  const std::uint8_t* p = index_.word_start + 8 * static_cast<std::size_t>(word);
  return static_cast<std::size_t>(ld64(p + 8) - ld64(p));
}

StatusOr<std::pair<const std::uint8_t*, std::size_t>> PlaceDatabase::stored_chunk(std::size_t i) const {
  if (i >= index_.scans) throw std::out_of_range("PlaceDatabase::stored_chunk: no stored scan " + std::to_string(i));
  const std::uint8_t* e = index_.entries + i * kEntryBytes;
  const std::uint64_t at = ld64(e), len = ld64(e + 8);
  // open() checked that the chunk lies inside the committed bytes.
  const std::uint8_t* c = bytes_.data + at;
  if (std::memcmp(c, "SCAN", 4) != 0 || ld64(c + 4) != len)
    return bad_data("place database: the index names scan " + std::to_string(i) + " at a byte that is not its SCAN chunk", at);
  if (crc(c, 12 + static_cast<std::size_t>(len)) != ld32(c + 12 + len))
    return bad_data("place database: CRC mismatch in the SCAN chunk of scan " + std::to_string(i), at + 12 + len);
  return std::make_pair(c, static_cast<std::size_t>(16 + len));
}

StatusOr<PlaceScan> PlaceDatabase::read_scan(std::size_t i) const {
  if (i >= size()) throw std::out_of_range("PlaceDatabase::scan: no scan " + std::to_string(i));
  if (i >= index_.scans) return added_[i - index_.scans];
  auto c = stored_chunk(i);
  if (!c.ok()) return c.status();
  DbHeader h;
  h.descriptor_dim = static_cast<std::uint16_t>(descriptor_dim_);
  h.descriptor_bits = static_cast<std::uint8_t>(storage_.descriptor_bits);
  h.storage = storage_;
  const std::uint64_t at = static_cast<std::uint64_t>(c.value().first - bytes_.data);
  return decode_scan(c.value().first + 12, c.value().second - 16, at + 12, h, alphabet_.size(), has_alphabet_);
}

PlaceScan PlaceDatabase::scan(std::size_t i) const {
  auto s = read_scan(i);
  if (!s.ok()) throw PlaceDataError(s.status());
  return std::move(s).value();
}

// --- writing ---

PlaceFileWriter::PlaceFileWriter(const PlaceStorageParams& storage, const Alphabet* alphabet, int descriptor_dim)
    : storage_(storage), alphabet_(alphabet), descriptor_dim_(descriptor_dim) {
  storage_.validate();
  if (descriptor_dim < 0 || descriptor_dim > static_cast<int>(kMaxDim))
    throw std::invalid_argument("PlaceFileWriter: descriptor_dim must be in [0, 4096]");
  if (descriptor_dim != 0 && storage_.descriptor == PlaceDescriptor::kPatch && alphabet != nullptr &&
      alphabet->descriptor_dim != descriptor_dim)
    throw std::invalid_argument("PlaceFileWriter: the alphabet's descriptors differ from descriptor_dim");
  if (descriptor_dim != 0 && storage_.descriptor == PlaceDescriptor::kVdlsd &&
      descriptor_dim != detail::stored_descriptor_dim(storage_, nullptr))
    throw std::invalid_argument("PlaceFileWriter: descriptor_dim differs from VD-LSD's");
}

PlaceFileWriter::PlaceFileWriter(const PlaceDatabase& db)
    : storage_(db.storage()), descriptor_dim_(db.descriptor_dim()) {
  if (db.file_info().major < 2 || !db.added_.empty())
    throw std::invalid_argument("PlaceFileWriter: appending needs a database opened from a 2.x file, with no scans added in memory");
  start_ = end_ = db.file_info().committed_bytes;
  sequence_ = db.file_info().commit_sequence + 1;
  const auto& ix = db.index_;
  for (std::size_t i = 0; i < ix.scans; ++i) {
    const std::uint8_t* e = ix.entries + i * kEntryBytes;
    offsets_.push_back(ld64(e));
    lengths_.push_back(ld64(e + 8));
    totals_.push_back(ld32(e + 16));
    names_.push_back(db.name(i));
  }
  if (db.vocabulary_ != nullptr) {
    vocabulary_ = db.vocabulary_;
    const auto& vx = db.vindex_;
    for (std::size_t i = 0; i < vx.scans; ++i) vtotals_.push_back(ld32(vx.entries + 12 * i));
    vinverted_.resize(vx.word_slots);
    for (std::uint32_t w = 0; w < vx.word_slots; ++w) {
      const std::uint64_t a = ld64(vx.word_start + 8 * static_cast<std::size_t>(w));
      const std::uint64_t b = ld64(vx.word_start + 8 * static_cast<std::size_t>(w) + 8);
      for (std::uint64_t k = a; k < b; ++k) vinverted_[w].emplace_back(ld32(vx.postings + 8 * k), ld32(vx.postings + 8 * k + 4));
    }
  }
  inverted_.resize(ix.word_slots);
  for (std::uint32_t w = 0; w < ix.word_slots; ++w) {
    const std::uint64_t a = ld64(ix.word_start + 8 * static_cast<std::size_t>(w));
    const std::uint64_t b = ld64(ix.word_start + 8 * static_cast<std::size_t>(w) + 8);
    inverted_[w].reserve(static_cast<std::size_t>(b - a));
    for (std::uint64_t k = a; k < b; ++k)
      inverted_[w].emplace_back(ld32(ix.postings + 8 * k), ld32(ix.postings + 8 * k + 4));
  }
}

PlaceFileWriter::Piece PlaceFileWriter::begin() {
  Piece p;
  p.offset = end_;
  if (end_ != 0) return p;  // appending
  p.bytes.assign(kMagic, kMagic + 8);
  Writer h;
  h.u16(kMajor);
  h.u16(vocabulary_ != nullptr ? kMinor : 0);  // 2.0 when nothing of 2.1 is needed
  h.u32(0);
  p.bytes.insert(p.bytes.end(), h.b.begin(), h.b.end());
  const std::uint32_t hc = crc(p.bytes.data(), 16);
  for (int i = 0; i < 4; ++i) p.bytes.push_back(static_cast<std::uint8_t>(hc >> (8 * i)));
  p.bytes.resize(kSlotsEnd, 0);  // two empty commit records
  put_chunk(p.bytes, "PHDR", phdr_payload(storage_, descriptor_dim_, alphabet_ != nullptr, 0));
  if (alphabet_ != nullptr) put_chunk(p.bytes, "ALPH", codec::encode_alphabet(*alphabet_));
  if (vocabulary_ != nullptr) put_chunk(p.bytes, "VOCB", encode_vocabulary(*vocabulary_));
  end_ = start_ = p.bytes.size();
  return p;
}

void PlaceFileWriter::set_vocabulary(std::shared_ptr<const PlaceVocabulary> vocabulary) {
  if (end_ != 0) throw std::logic_error("PlaceFileWriter::set_vocabulary after begin");
  if (vocabulary != nullptr && (vocabulary->empty() || (descriptor_dim_ != 0 && vocabulary->descriptor_dim != descriptor_dim_)))
    throw std::invalid_argument("PlaceFileWriter::set_vocabulary: the vocabulary is empty or its descriptors differ from descriptor_dim");
  vocabulary_ = std::move(vocabulary);
}

void PlaceFileWriter::vocab_index(const PlaceScan& scan) {
  if (vocabulary_ == nullptr) return;
  const auto index = static_cast<std::uint32_t>(vtotals_.size());
  std::uint32_t total = 0;
  for (const auto& [word, count] : detail::vocabulary_words(*vocabulary_, scan)) {
    if (word >= vinverted_.size()) vinverted_.resize(static_cast<std::size_t>(word) + 1);
    vinverted_[word].emplace_back(index, count);
    total += count;
  }
  vtotals_.push_back(total);
}

void PlaceFileWriter::index(std::uint64_t chunk_offset, std::uint64_t payload_length, const std::string& name,
                            const std::vector<std::pair<std::uint32_t, std::uint32_t>>& words) {
  if (names_.size() >= kMaxScans) throw std::invalid_argument("PlaceFileWriter: more than 2^24 scans");
  const auto index = static_cast<std::uint32_t>(names_.size());
  std::uint32_t total = 0;
  for (const auto& [word, count] : words) {
    if (word >= kMaxWordSlots) throw std::invalid_argument("PlaceFileWriter: word id beyond 2^24");
    if (word >= inverted_.size()) inverted_.resize(static_cast<std::size_t>(word) + 1);
    inverted_[word].emplace_back(index, count);
    total += count;
  }
  offsets_.push_back(chunk_offset);
  lengths_.push_back(payload_length);
  names_.push_back(name.substr(0, kMaxName));
  totals_.push_back(total);
}

PlaceFileWriter::Piece PlaceFileWriter::add(const PlaceScan& scan) {
  if (end_ == 0) throw std::logic_error("PlaceFileWriter::add before begin");
  if (scan.descriptor != storage_.descriptor)
    throw std::invalid_argument("PlaceFileWriter::add: scan '" + scan.name + "' has " + to_string(scan.descriptor) +
                                " descriptors, the database " + to_string(storage_.descriptor));
  if (!scan.features.empty() && scan.descriptor_dim != descriptor_dim_)
    throw std::invalid_argument("PlaceFileWriter::add: scan '" + scan.name + "' has descriptors of " +
                                std::to_string(scan.descriptor_dim) + " values, the database " +
                                std::to_string(descriptor_dim_));
  if (scan.descriptor_bits != storage_.descriptor_bits)
    throw std::invalid_argument("PlaceFileWriter::add: scan '" + scan.name + "' was quantised to " +
                                std::to_string(scan.descriptor_bits) + " bits, the database uses " +
                                std::to_string(storage_.descriptor_bits));
  for (std::size_t i = 1; i < scan.words.size(); ++i)
    if (scan.words[i].first <= scan.words[i - 1].first)
      throw std::invalid_argument("PlaceFileWriter::add: scan '" + scan.name + "' has unsorted word ids");
  Piece p;
  p.offset = end_;
  const auto payload = detail::encode_scan_payload(scan, storage_.range_step);
  put_chunk(p.bytes, "SCAN", payload);
  index(end_, payload.size(), scan.name, scan.words);
  vocab_index(scan);
  end_ += p.bytes.size();
  return p;
}

StatusOr<PlaceFileWriter::Piece> PlaceFileWriter::copy(const PlaceDatabase& db, std::size_t i) {
  if (end_ == 0) throw std::logic_error("PlaceFileWriter::copy before begin");
  auto c = db.stored_chunk(i);
  if (!c.ok()) return c.status();
  // The words come from the decoded entry (they are what the index must say).
  auto s = db.read_scan(i);
  if (!s.ok()) return s.status();
  Piece p;
  p.offset = end_;
  p.bytes.assign(c.value().first, c.value().first + c.value().second);
  index(end_, c.value().second - 16, s.value().name, s.value().words);
  vocab_index(s.value());
  end_ += p.bytes.size();
  return p;
}

std::pair<PlaceFileWriter::Piece, PlaceFileWriter::Piece> PlaceFileWriter::finish() {
  if (end_ == 0) throw std::logic_error("PlaceFileWriter::finish before begin");
  Piece idx;
  idx.offset = end_;
  if (vocabulary_ != nullptr)  // VIDX right before PIDX (formats/place_db.md §3.6)
    idx.bytes = chunk_bytes("VIDX", encode_vindex(vtotals_, vocabulary_->nodes(), vinverted_));
  const std::uint64_t pidx_at = end_ + idx.bytes.size();
  const auto pidx = chunk_bytes("PIDX", encode_index(offsets_, lengths_, names_, totals_, inverted_));
  idx.bytes.insert(idx.bytes.end(), pidx.begin(), pidx.end());
  const std::uint64_t end = end_ + idx.bytes.size();
  Piece commit;
  commit.offset = slot_offset(sequence_);
  commit.bytes = commit_slot(sequence_, end, pidx_at);
  return {std::move(idx), std::move(commit)};
}

std::vector<std::uint8_t> PlaceDatabase::save() const {
  int dim = descriptor_dim_;
  if (dim == 0) dim = detail::stored_descriptor_dim(storage_, has_alphabet_ ? &alphabet_ : nullptr);
  PlaceFileWriter w(storage_, has_alphabet_ ? &alphabet_ : nullptr, dim);
  w.set_vocabulary(vocabulary_);
  std::vector<std::uint8_t> out;
  auto put = [&](const PlaceFileWriter::Piece& p) {
    if (out.size() < p.offset + p.bytes.size()) out.resize(static_cast<std::size_t>(p.offset + p.bytes.size()));
    std::memcpy(out.data() + p.offset, p.bytes.data(), p.bytes.size());
  };
  put(w.begin());
  for (std::size_t i = 0; i < index_.scans; ++i) {
    auto p = w.copy(*this, i);
    if (!p.ok()) throw PlaceDataError(p.status());
    put(p.value());
  }
  for (const auto& s : added_) put(w.add(s));
  const auto [idx, commit] = w.finish();
  put(idx);
  put(commit);
  return out;
}

// --- reading ---

namespace {

struct ParsedIndex {
  std::uint32_t scans = 0, word_slots = 0;
  std::uint64_t postings = 0, names_length = 0;
  const std::uint8_t* entries = nullptr;
  const std::uint8_t* names = nullptr;
  const std::uint8_t* word_start = nullptr;
  const std::uint8_t* postings_at = nullptr;
};

// Checks a PIDX payload: sizes, entries inside [first, last) without overlap, names inside
// the name bytes, word starts non-decreasing, postings (scan < N, increasing within a word,
// count >= 1) summing to each entry's word total, word ids below the alphabet size.
StatusOr<ParsedIndex> parse_index(const std::uint8_t* p, std::size_t len, std::uint64_t at, std::uint64_t first,
                                  std::uint64_t last, std::size_t alphabet_words, bool has_alphabet) {
  if (len < 24) return bad_data("place database: PIDX too short", at);
  ParsedIndex x;
  x.scans = ld32(p);
  x.word_slots = ld32(p + 4);
  x.postings = ld64(p + 8);
  x.names_length = ld64(p + 16);
  if (x.scans > kMaxScans) return bad_data("place database: PIDX scan count " + std::to_string(x.scans) + " too large", at);
  if (x.word_slots > kMaxWordSlots || (has_alphabet && x.word_slots > alphabet_words))
    return bad_data("place database: PIDX word count " + std::to_string(x.word_slots) + " out of range", at + 4);
  // Sizes in 64 bits from values already bounded: no overflow.
  const std::uint64_t left = len - 24;
  const std::uint64_t fixed = static_cast<std::uint64_t>(x.scans) * kEntryBytes + 8 * (static_cast<std::uint64_t>(x.word_slots) + 1);
  if (fixed > left || x.names_length > left - fixed || x.postings > (left - fixed - x.names_length) / 8 ||
      fixed + x.names_length + 8 * x.postings != left)
    return bad_data("place database: PIDX sizes do not add up to its length", at + 8);
  x.entries = p + 24;
  x.names = x.entries + static_cast<std::size_t>(x.scans) * kEntryBytes;
  x.word_start = x.names + x.names_length;
  x.postings_at = x.word_start + 8 * (static_cast<std::size_t>(x.word_slots) + 1);
  std::uint64_t prev_end = first;
  for (std::uint32_t i = 0; i < x.scans; ++i) {
    const std::uint8_t* e = x.entries + static_cast<std::size_t>(i) * kEntryBytes;
    const std::uint64_t e_at = at + 24 + static_cast<std::uint64_t>(i) * kEntryBytes;
    const std::uint64_t off = ld64(e), plen = ld64(e + 8);
    if (off < prev_end || off > last || plen > last - off || last - off - plen < 16)
      return bad_data("place database: PIDX entry " + std::to_string(i) + " points outside the scan chunks", e_at);
    prev_end = off + 16 + plen;
    const std::uint64_t name_at = ld32(e + 20), name_len = ld16(e + 24);
    if (name_at > x.names_length || name_len > x.names_length - name_at || name_len > kMaxName || ld16(e + 26) != 0)
      return bad_data("place database: PIDX entry " + std::to_string(i) + " has a bad name", e_at + 20);
    const double n2 = ldf64(e + 28);
    if (!std::isfinite(n2) || n2 < 0.0) return bad_data("place database: PIDX entry " + std::to_string(i) + " has a bad norm", e_at + 28);
  }
  const std::uint64_t ws_at = at + 24 + static_cast<std::uint64_t>(x.scans) * kEntryBytes + x.names_length;
  if (ld64(x.word_start) != 0 || ld64(x.word_start + 8 * static_cast<std::size_t>(x.word_slots)) != x.postings)
    return bad_data("place database: PIDX word starts do not cover the postings", ws_at);
  for (std::uint32_t w = 0; w < x.word_slots; ++w)
    if (ld64(x.word_start + 8 * static_cast<std::size_t>(w) + 8) < ld64(x.word_start + 8 * static_cast<std::size_t>(w)))
      return bad_data("place database: PIDX word starts decrease", ws_at + 8 * (static_cast<std::uint64_t>(w) + 1));
  std::vector<std::uint64_t> sums(x.scans, 0);
  const std::uint64_t post_at = ws_at + 8 * (static_cast<std::uint64_t>(x.word_slots) + 1);
  for (std::uint32_t w = 0; w < x.word_slots; ++w) {
    const std::uint64_t a = ld64(x.word_start + 8 * static_cast<std::size_t>(w));
    const std::uint64_t b = ld64(x.word_start + 8 * static_cast<std::size_t>(w) + 8);
    if (b < a || b > x.postings) return bad_data("place database: PIDX word starts decrease", ws_at + 8 * (w + 1));
    for (std::uint64_t k = a; k < b; ++k) {
      const std::uint32_t s = ld32(x.postings_at + 8 * k), c = ld32(x.postings_at + 8 * k + 4);
      if (s >= x.scans || c == 0 || (k > a && s <= ld32(x.postings_at + 8 * (k - 1))))
        return bad_data("place database: PIDX posting is out of range, unsorted or zero", post_at + 8 * k);
      sums[s] += c;
    }
  }
  for (std::uint32_t i = 0; i < x.scans; ++i)
    if (static_cast<std::uint32_t>(sums[i]) != ld32(x.entries + static_cast<std::size_t>(i) * kEntryBytes + 16))
      return bad_data("place database: PIDX word total of scan " + std::to_string(i) + " differs from its postings",
                      at + 24 + static_cast<std::uint64_t>(i) * kEntryBytes + 16);
  return x;
}

// The name and words of a 1.0 SCAN payload (the rest is checked when the scan is read).
Status scan_words(const std::uint8_t* p, std::size_t n, std::uint64_t base, std::size_t alphabet_words, bool has_alphabet,
                  std::string& name, std::vector<std::pair<std::uint32_t, std::uint32_t>>& words) {
  Reader r(p, n, base);
  std::uint16_t name_len = 0;
  if (!r.u16(name_len)) return bad_data("place database: SCAN chunk truncated in the name", r.offset());
  if (name_len > kMaxName) return bad_data("place database: scan name too long", r.offset() - 2);
  const std::uint8_t* nm = r.take(name_len);
  if (nm == nullptr || r.take(1 + 192) == nullptr) return bad_data("place database: SCAN chunk truncated", r.offset());
  name.assign(reinterpret_cast<const char*>(nm), name_len);
  std::uint32_t nw = 0;
  if (!r.u32(nw)) return bad_data("place database: SCAN chunk truncated in the word count", r.offset());
  if (static_cast<std::uint64_t>(nw) * 8 > r.left())
    return bad_data("place database: word count " + std::to_string(nw) + " does not fit the chunk", r.offset() - 4);
  words.clear();
  words.reserve(nw);
  for (std::uint32_t i = 0; i < nw; ++i) {
    std::uint32_t word = 0, count = 0;
    r.u32(word);
    r.u32(count);
    if ((i > 0 && word <= words.back().first) || count == 0 || (has_alphabet && word >= alphabet_words) || word >= kMaxWordSlots)
      return bad_data("place database: bad word entry (unsorted, zero count or unknown word)", r.offset() - 8);
    words.emplace_back(word, count);
  }
  return {};
}

}  // namespace

StatusOr<PlaceDatabase> PlaceDatabase::load(const std::vector<std::uint8_t>& bytes) {
  return open(SharedBytes::copy_of(bytes));
}

StatusOr<PlaceDatabase> PlaceDatabase::open(SharedBytes file) {
  const std::uint8_t* bytes = file.data;
  const std::uint64_t size = file.size;
  if (size < kHeaderBytes) return bad_data("place database: file too short for its header", size);
  if (std::memcmp(bytes, kMagic, 8) != 0) return bad_data("not a lex3d place database (bad magic)", 0);
  const std::uint16_t major = ld16(bytes + 8), minor = ld16(bytes + 10);
  const std::uint32_t flags = ld32(bytes + 12), hcrc = ld32(bytes + 16);
  // The version first: a newer major version may lay out its header differently.
  if (major > kMajor)
    return bad_data("place database: format version " + std::to_string(major) + "." + std::to_string(minor) +
                        " is newer than this lex3d reads (1.0 and 2.x); use a newer lex3d",
                    8);
  if (major != 1 && major != 2) return bad_data("place database: unsupported major version " + std::to_string(major), 8);
  if (crc(bytes, 16) != hcrc) return bad_data("place database: header CRC mismatch", 16);
  if (flags != 0) return bad_data("place database: reserved header flag set", 12);
  PlaceDatabase db;
  db.bytes_ = file;
  db.info_.major = major;
  db.info_.minor = minor;
  Phdr h;
  std::uint64_t pos = 0;
  std::uint64_t limit = size;
  std::uint64_t index_at = 0;
  if (major == 2) {
    if (size < kSlotsEnd) return bad_data("place database: file too short for its commit records", size);
    // The valid commit record with the highest sequence number is in force.
    std::uint64_t seq = 0;
    for (int k = 0; k < 2; ++k) {
      const std::uint8_t* s = bytes + 20 + kSlotBytes * static_cast<std::size_t>(k);
      if (crc(s, 24) != ld32(s + 24) || ld64(s) == 0 || slot_offset(ld64(s)) != 20 + kSlotBytes * static_cast<std::size_t>(k))
        continue;
      if (ld64(s) > seq) {
        seq = ld64(s);
        limit = ld64(s + 8);
        index_at = ld64(s + 16);
      }
    }
    if (seq == 0) return bad_data("place database: no valid commit record (bytes 20-75)", 20);
    if (limit > size)
      return bad_data("place database: truncated: the committed database ends at byte " + std::to_string(limit) +
                          ", the file at byte " + std::to_string(size),
                      size);
    db.info_.commit_sequence = seq;
    db.info_.committed_bytes = limit;
    db.info_.ignored_tail_bytes = size - limit;
    pos = kSlotsEnd;
  } else {
    pos = kHeaderBytes;
  }
  auto ph = read_chunk(bytes, limit, pos);
  if (!ph.ok()) return ph.status();
  auto hp = parse_phdr(ph.value());
  if (!hp.ok()) return hp.status();
  h = hp.value();
  if (major == 2 && h.scan_count != 0) return bad_data("place database: PHDR scan_count must be 0 in format 2", ph.value().at + 12);
  db.storage_ = h.storage;
  db.descriptor_dim_ = h.descriptor_dim;
  pos += 16 + ph.value().length;
  if (h.has_alphabet) {
    auto ac = read_chunk(bytes, limit, pos);
    if (!ac.ok()) return ac.status();
    if (ac.value().type != "ALPH") return bad_data("place database: ALPH chunk missing after PHDR", pos);
    auto a = codec::decode_alphabet(std::vector<std::uint8_t>(ac.value().payload, ac.value().payload + ac.value().length));
    if (!a.ok()) return bad_data("place database: ALPH: " + a.status().message(), pos + 12 + a.status().offset().value_or(0));
    if (h.descriptor_dim != 0 && h.storage.descriptor == PlaceDescriptor::kPatch &&
        a.value().descriptor_dim != h.descriptor_dim)
      return bad_data("place database: the alphabet's descriptor size differs from PHDR's", pos + 12);
    db.set_alphabet(std::move(a).value());
    pos += 16 + ac.value().length;
  }
  // 2.1: the recognition vocabulary, right after ALPH (or PHDR) when there is one. The chunk
  // there is read whatever it is (CRC checked), so a damaged type cannot hide a vocabulary.
  std::optional<StatusOr<ChunkView>> next;
  if (major == 2 && minor >= 1 && pos < index_at) next = read_chunk(bytes, limit, pos);
  if (next && !next->ok()) return next->status();
  if (next && next->value().type == "VOCB") {
    auto& vc = *next;
    auto v = decode_vocabulary(vc.value().payload, vc.value().length, pos + 12);
    if (!v.ok()) return v.status();
    if (h.descriptor_dim != 0 && v.value().descriptor_dim != h.descriptor_dim)
      return bad_data("place database: the vocabulary's descriptor size differs from PHDR's", pos + 12);
    db.vocabulary_ = std::make_shared<const PlaceVocabulary>(std::move(v).value());
    pos += 16 + vc.value().length;
  }
  const std::uint64_t first = pos;
  const std::uint8_t* index_payload = nullptr;
  std::size_t index_length = 0;
  std::uint64_t index_payload_at = 0;
  if (major == 2) {
    if (index_at < first) return bad_data("place database: the commit record's index offset is before the scans", 20);
    auto ic = read_chunk(bytes, limit, index_at);
    if (!ic.ok()) return ic.status();
    if (ic.value().type != "PIDX") return bad_data("place database: the commit record does not point at a PIDX chunk", index_at);
    if (index_at + 16 + ic.value().length != limit)
      return bad_data("place database: the PIDX chunk does not end the committed database", index_at + 4);
    index_payload = ic.value().payload;
    index_length = ic.value().length;
    index_payload_at = index_at + 12;
  } else {
    // 1.0: every chunk is read (CRC checked) and the index built from the SCAN words.
    std::vector<std::uint64_t> offsets, lengths;
    std::vector<std::string> names;
    std::vector<std::uint32_t> totals;
    std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> inverted;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> words;
    std::string name;
    while (true) {
      if (size - pos < 16) return bad_data("place database: truncated chunk (no end chunk)", pos);
      auto c = read_chunk(bytes, size, pos);
      if (!c.ok()) return c.status();
      const ChunkView& cv = c.value();
      if (cv.type == "SCAN") {
        if (names.size() >= h.scan_count) return bad_data("place database: more SCAN chunks than PHDR's scan count", pos);
        Status st = scan_words(cv.payload, cv.length, pos + 12, db.alphabet_.size(), db.has_alphabet_, name, words);
        if (!st.ok()) return st;
        const auto s = static_cast<std::uint32_t>(names.size());
        std::uint32_t total = 0;
        for (const auto& [w, n] : words) {
          if (w >= inverted.size()) inverted.resize(static_cast<std::size_t>(w) + 1);
          inverted[w].emplace_back(s, n);
          total += n;
        }
        offsets.push_back(pos);
        lengths.push_back(cv.length);
        names.push_back(name);
        totals.push_back(total);
      } else if (cv.type == "PEND") {
        if (cv.length != 0) return bad_data("place database: PEND chunk is not empty", pos + 4);
        if (names.size() != h.scan_count)
          return bad_data("place database: " + std::to_string(names.size()) + " SCAN chunks, PHDR says " +
                              std::to_string(h.scan_count),
                          pos);
        if (pos + 16 != size) return bad_data("place database: bytes after the end chunk", pos + 16);
        break;
      } else if (cv.type == "ALPH" || cv.type == "PHDR" || cv.type == "PIDX") {
        return bad_data("place database: unexpected " + cv.type + " chunk", pos);
      } else if (std::isupper(static_cast<unsigned char>(cv.type[0]))) {
        return bad_data("place database: unknown required chunk '" + cv.type + "'", pos);
      }
      pos += 16 + cv.length;
    }
    auto built = std::make_shared<const std::vector<std::uint8_t>>(encode_index(offsets, lengths, names, totals, inverted));
    db.built_index_ = built;
    index_payload = built->data();
    index_length = built->size();
    index_payload_at = 0;  // offsets in a built index are not file offsets
    limit = size;
    index_at = size;
  }
  // The vocabulary's index ends where PIDX begins; its payload's last 8 bytes are its length.
  std::uint64_t scans_end = index_at;
  if (db.vocabulary_ != nullptr) {
    if (index_at < first + 16 + 24) return bad_data("place database: VIDX chunk missing before PIDX", index_at);
    const std::uint64_t vlen = ld64(bytes + index_at - 12);
    if (vlen < 24 || vlen > index_at - first - 16)
      return bad_data("place database: VIDX chunk missing before PIDX (bad length; an older lex3d may have appended to "
                      "this file: rewrite it with lex3d place upgrade after removing the vocabulary)",
                      index_at - 12);
    const std::uint64_t vat = index_at - 16 - vlen;
    auto vc = read_chunk(bytes, index_at, vat);
    if (!vc.ok()) return vc.status();
    if (vc.value().type != "VIDX" || vc.value().length != vlen)
      return bad_data("place database: VIDX chunk missing before PIDX", vat);
    const std::uint8_t* v = vc.value().payload;
    const std::uint64_t at = vat + 12;
    StoredVocabIndex vx;
    vx.scans = ld32(v);
    vx.word_slots = ld32(v + 4);
    const std::uint64_t np = ld64(v + 8);
    if (vx.word_slots != db.vocabulary_->nodes())
      return bad_data("place database: VIDX word count differs from the vocabulary's nodes", at + 4);
    if (vx.scans > kMaxScans) return bad_data("place database: VIDX scan count too large", at);
    const std::uint64_t fixed = 16 + 12ull * vx.scans + 8ull * (static_cast<std::uint64_t>(vx.word_slots) + 1) + 8;
    if (fixed > vlen || np > (vlen - fixed) / 8 || fixed + 8 * np != vlen)
      return bad_data("place database: VIDX sizes do not add up to its length", at + 8);
    vx.entries = v + 16;
    vx.word_start = vx.entries + 12ull * vx.scans;
    vx.postings = vx.word_start + 8 * (static_cast<std::size_t>(vx.word_slots) + 1);
    const std::uint64_t ws_at = at + 16 + 12ull * vx.scans;
    for (std::uint32_t i = 0; i < vx.scans; ++i) {
      const double n2 = ldf64(vx.entries + 12ull * i + 4);
      if (!std::isfinite(n2) || n2 < 0.0) return bad_data("place database: VIDX entry " + std::to_string(i) + " has a bad norm", at + 16 + 12ull * i + 4);
    }
    if (ld64(vx.word_start) != 0 || ld64(vx.word_start + 8 * static_cast<std::size_t>(vx.word_slots)) != np)
      return bad_data("place database: VIDX word starts do not cover the postings", ws_at);
    std::vector<std::uint64_t> sums(vx.scans, 0);
    const std::uint64_t post_at = ws_at + 8 * (static_cast<std::uint64_t>(vx.word_slots) + 1);
    for (std::uint32_t w = 0; w < vx.word_slots; ++w) {
      const std::uint64_t a = ld64(vx.word_start + 8 * static_cast<std::size_t>(w));
      const std::uint64_t b = ld64(vx.word_start + 8 * static_cast<std::size_t>(w) + 8);
      if (b < a || b > np) return bad_data("place database: VIDX word starts decrease", ws_at + 8 * (w + 1ull));
      for (std::uint64_t k = a; k < b; ++k) {
        const std::uint32_t s = ld32(vx.postings + 8 * k), c = ld32(vx.postings + 8 * k + 4);
        if (s >= vx.scans || c == 0 || (k > a && s <= ld32(vx.postings + 8 * (k - 1))))
          return bad_data("place database: VIDX posting is out of range, unsorted or zero", post_at + 8 * k);
        sums[s] += c;
      }
    }
    for (std::uint32_t i = 0; i < vx.scans; ++i)
      if (sums[i] != ld32(vx.entries + 12ull * i))
        return bad_data("place database: VIDX word total of scan " + std::to_string(i) + " differs from its postings",
                        at + 16 + 12ull * i);
    db.vindex_ = vx;
    scans_end = vat;
  }
  auto ix = parse_index(index_payload, index_length, index_payload_at, first, scans_end, db.alphabet_.size(), db.has_alphabet_);
  if (!ix.ok()) return ix.status();
  if (db.vocabulary_ != nullptr && ix.value().scans != db.vindex_.scans)
    return bad_data("place database: VIDX and PIDX count different scans", index_at + 12);
  const ParsedIndex& x = ix.value();
  db.index_.scans = x.scans;
  db.index_.word_slots = x.word_slots;
  db.index_.entries = x.entries;
  db.index_.names = x.names;
  db.index_.names_length = x.names_length;
  db.index_.word_start = x.word_start;
  db.index_.postings = x.postings_at;
  db.info_.index_bytes = index_length + 16;
  if (major == 2) {
    std::uint64_t live = first + index_length + 16 + (index_at - scans_end);  // + VIDX
    for (std::uint32_t i = 0; i < x.scans; ++i) live += 16 + ld64(x.entries + static_cast<std::size_t>(i) * kEntryBytes + 8);
    db.info_.dead_bytes = limit - live;
  }
  return db;
}

// A prepared query as bytes (formats/place_db.md §6): "L3PQ", u16 descriptor values, u8
// descriptor bits, u64 payload length, the SCAN payload, u32 features, their rotations as
// f32 w x y z, and the CRC-32 of everything before it.
std::vector<std::uint8_t> encode_place_query(const PlaceScan& scan, const PlaceStorageParams& storage) {
  storage.validate();
  if (scan.descriptor_bits != storage.descriptor_bits)
    throw std::invalid_argument("encode_place_query: the scan was quantised to " + std::to_string(scan.descriptor_bits) +
                                " bits, the storage parameters say " + std::to_string(storage.descriptor_bits));
  if (scan.descriptor != storage.descriptor)
    throw std::invalid_argument(std::string("encode_place_query: the scan has ") + to_string(scan.descriptor) +
                                " descriptors, the storage parameters " + to_string(storage.descriptor));
  const std::vector<std::uint8_t> payload = detail::encode_scan_payload(scan, storage.range_step);
  Writer w;
  w.bytes(reinterpret_cast<const std::uint8_t*>("L3PQ"), 4);
  w.u16(static_cast<std::uint16_t>(scan.descriptor_dim));
  w.u8(static_cast<std::uint8_t>(scan.descriptor_bits));
  w.u64(payload.size());
  w.bytes(payload.data(), payload.size());
  w.u32(static_cast<std::uint32_t>(scan.features.size()));
  for (const auto& f : scan.features) {
    w.f32(f.rotation.w());
    w.f32(f.rotation.x());
    w.f32(f.rotation.y());
    w.f32(f.rotation.z());
  }
  w.u32(crc(w.b.data(), w.b.size()));
  return std::move(w.b);
}

StatusOr<PlaceScan> decode_place_query(const std::uint8_t* data, std::size_t size, const PlaceStorageParams& storage) {
  if (size < 4 + 2 + 1 + 8 + 4 + 4 || std::memcmp(data, "L3PQ", 4) != 0)
    return bad_data("place query: not a prepared query (no L3PQ header)", 0);
  if (crc(data, size - 4) != detail::ld32(data + size - 4)) return bad_data("place query: CRC mismatch", size - 4);
  Reader r(data, size - 4, 0);
  r.take(4);
  DbHeader h;
  h.storage = storage;
  r.u16(h.descriptor_dim);
  r.u8(h.descriptor_bits);
  if (h.descriptor_dim > kMaxDim || h.descriptor_bits != storage.descriptor_bits)
    return bad_data("place query: descriptor layout (" + std::to_string(h.descriptor_dim) + " values, " +
                        std::to_string(h.descriptor_bits) + " bits) does not fit the database's storage",
                    4);
  std::uint64_t length = 0;
  r.u64(length);
  if (length > r.left()) return bad_data("place query: payload length " + std::to_string(length) + " does not fit", 7);
  const std::uint64_t at = r.offset();
  const std::uint8_t* payload = r.take(static_cast<std::size_t>(length));
  auto scan = decode_scan(payload, static_cast<std::size_t>(length), at, h, 0, false);
  if (!scan.ok()) return scan.status();
  PlaceScan s = std::move(scan).value();
  std::uint32_t nf = 0;
  if (!r.u32(nf) || nf != s.features.size() || static_cast<std::uint64_t>(nf) * 16 != r.left())
    return bad_data("place query: the rotations do not match the features", r.offset());
  for (auto& f : s.features) {
    float q[4] = {};
    for (float& v : q) r.f32(v);
    const Eigen::Quaternionf rot(q[0], q[1], q[2], q[3]);
    if (!rot.coeffs().allFinite() || std::abs(rot.norm() - 1.0F) > 1e-3F)
      return bad_data("place query: a feature rotation is not a unit quaternion", r.offset() - 16);
    f.rotation = rot;
  }
  detail::finish_place_scan(s);
  return s;
}

}  // namespace lex3d
