// The place database byte format (formats/place_db.md): header, chunks with CRCs,
// every length checked against the bytes left and a cap before allocating.

#include <zlib.h>

#include <cmath>
#include <cctype>
#include <cstring>
#include <limits>
#include <string>

#include "lex3d/codec/codec.hpp"
#include "lex3d/place/place.hpp"
#include "place/internal.hpp"

namespace lex3d {

namespace {

constexpr char kMagic[8] = {'L', 'E', 'X', '3', 'D', 'P', 'D', 'B'};
constexpr std::uint16_t kMajor = 1;
constexpr std::uint16_t kMinor = 0;
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

std::vector<std::uint8_t> PlaceDatabase::save() const {
  std::vector<std::uint8_t> out(kMagic, kMagic + 8);
  Writer h;
  h.u16(kMajor);
  h.u16(kMinor);
  h.u32(0);
  out.insert(out.end(), h.b.begin(), h.b.end());
  const std::uint32_t hc = crc(out.data(), 16);
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(hc >> (8 * i)));
  int dim = 0;
  for (const auto& s : scans_)
    if (!s.features.empty()) dim = s.descriptor_dim;
  if (dim == 0 && has_alphabet_) dim = alphabet_.descriptor_dim;
  Writer p;
  p.u32(static_cast<std::uint32_t>(scans_.size()));
  p.u16(static_cast<std::uint16_t>(dim));
  p.u8(static_cast<std::uint8_t>(storage_.descriptor_bits));
  p.u8(has_alphabet_ ? 1 : 0);
  p.u32(static_cast<std::uint32_t>(storage_.max_features));
  p.f64(storage_.coarse_azimuth_deg);
  p.u16(static_cast<std::uint16_t>(storage_.coarse_row_factor));
  p.u16(0);
  p.f64(storage_.range_step);
  put_chunk(out, "PHDR", p.b);
  if (has_alphabet_) put_chunk(out, "ALPH", codec::encode_alphabet(alphabet_));
  for (const auto& s : scans_) put_chunk(out, "SCAN", detail::encode_scan_payload(s, storage_.range_step));
  put_chunk(out, "PEND", {});
  return out;
}

StatusOr<PlaceDatabase> PlaceDatabase::load(const std::vector<std::uint8_t>& bytes) {
  if (bytes.size() < kHeaderBytes) return bad_data("place database: file too short for its header", bytes.size());
  if (std::memcmp(bytes.data(), kMagic, 8) != 0) return bad_data("not a lex3d place database (bad magic)", 0);
  Reader hr(bytes.data() + 8, 12, 8);
  std::uint16_t major = 0, minor = 0;
  std::uint32_t flags = 0, hcrc = 0;
  hr.u16(major);
  hr.u16(minor);
  hr.u32(flags);
  hr.u32(hcrc);
  if (major != kMajor) return bad_data("place database: unsupported major version " + std::to_string(major), 8);
  if (crc(bytes.data(), 16) != hcrc) return bad_data("place database: header CRC mismatch", 16);
  if (flags != 0) return bad_data("place database: reserved header flag set", 12);
  DbHeader h;
  bool has_alphabet_flag = false;
  PlaceDatabase db;
  std::size_t pos = kHeaderBytes;
  int stage = 0;  // 0 expect PHDR, 1 expect ALPH/SCAN/PEND, 2 done
  std::size_t scans_seen = 0;
  while (true) {
    if (bytes.size() - pos < 16) return bad_data("place database: truncated chunk (no end chunk)", pos);
    char type[5] = {0, 0, 0, 0, 0};
    std::memcpy(type, bytes.data() + pos, 4);
    Reader lr(bytes.data() + pos + 4, 8, pos + 4);
    std::uint64_t len = 0;
    lr.u64(len);
    for (int i = 0; i < 4; ++i)
      if (!std::isalpha(static_cast<unsigned char>(type[i])))
        return bad_data("place database: chunk type is not 4 letters", pos);
    if (len > bytes.size() - pos - 16)
      return bad_data("place database: chunk '" + std::string(type) + "' length " + std::to_string(len) +
                          " exceeds the file",
                      pos + 4);
    const auto plen = static_cast<std::size_t>(len);
    const std::uint8_t* payload = bytes.data() + pos + 12;
    Reader cr(payload + plen, 4, pos + 12 + plen);
    std::uint32_t ccrc = 0;
    cr.u32(ccrc);
    if (crc(bytes.data() + pos, 12 + plen) != ccrc)
      return bad_data("place database: CRC mismatch in chunk '" + std::string(type) + "'", pos + 12 + plen);
    const std::string t(type);
    const std::uint64_t at = pos + 12;
    if (stage == 0) {
      if (t != "PHDR") return bad_data("place database: first chunk is '" + t + "', not PHDR", pos);
      if (plen != kPhdrBytes) return bad_data("place database: PHDR has " + std::to_string(plen) + " bytes, not 32", pos + 4);
      Reader r(payload, plen, at);
      std::uint8_t alph = 0;
      std::uint32_t maxf = 0;
      std::uint16_t rowf = 0, reserved = 0;
      r.u32(h.scan_count);
      r.u16(h.descriptor_dim);
      r.u8(h.descriptor_bits);
      r.u8(alph);
      r.u32(maxf);
      r.f64(h.storage.coarse_azimuth_deg);
      r.u16(rowf);
      r.u16(reserved);
      r.f64(h.storage.range_step);
      h.storage.max_features = static_cast<int>(std::min<std::uint32_t>(maxf, 1u << 30));
      h.storage.descriptor_bits = h.descriptor_bits;
      h.storage.coarse_row_factor = rowf;
      if (h.scan_count > kMaxScans || h.descriptor_dim > kMaxDim || alph > 1 || reserved != 0)
        return bad_data("place database: PHDR field out of range", at);
      try {
        h.storage.validate();
      } catch (const std::invalid_argument& e) {
        return bad_data(std::string("place database: PHDR: ") + e.what(), at);
      }
      has_alphabet_flag = alph == 1;
      db = PlaceDatabase(h.storage);
      stage = 1;
    } else if (t == "ALPH") {
      if (!has_alphabet_flag || db.has_alphabet() || scans_seen > 0)
        return bad_data("place database: unexpected ALPH chunk", pos);
      auto a = codec::decode_alphabet(std::vector<std::uint8_t>(payload, payload + plen));
      if (!a.ok()) return bad_data("place database: ALPH: " + a.status().message(), at + a.status().offset().value_or(0));
      if (h.descriptor_dim != 0 && a.value().descriptor_dim != h.descriptor_dim)
        return bad_data("place database: the alphabet's descriptor size differs from PHDR's", at);
      db.set_alphabet(std::move(a).value());
    } else if (t == "SCAN") {
      if (has_alphabet_flag && !db.has_alphabet()) return bad_data("place database: SCAN before the ALPH chunk", pos);
      if (scans_seen >= h.scan_count) return bad_data("place database: more SCAN chunks than PHDR's scan count", pos);
      auto s = decode_scan(payload, plen, at, h, db.alphabet().size(), db.has_alphabet());
      if (!s.ok()) return s.status();
      db.add(std::move(s).value());
      ++scans_seen;
    } else if (t == "PEND") {
      if (plen != 0) return bad_data("place database: PEND chunk is not empty", pos + 4);
      if (has_alphabet_flag && !db.has_alphabet()) return bad_data("place database: ALPH chunk missing", pos);
      if (scans_seen != h.scan_count)
        return bad_data("place database: " + std::to_string(scans_seen) + " SCAN chunks, PHDR says " +
                            std::to_string(h.scan_count),
                        pos);
      pos += 16;
      if (pos != bytes.size()) return bad_data("place database: bytes after the end chunk", pos);
      return db;
    } else if (std::isupper(static_cast<unsigned char>(type[0]))) {
      return bad_data("place database: unknown required chunk '" + t + "'", pos);
    }
    // Unknown optional chunks are skipped (their CRC was checked).
    pos += 16 + plen;
  }
}

}  // namespace lex3d
