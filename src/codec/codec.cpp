// The model file and alphabet file (formats/model.md, formats/alphabet.md). Field and
// chunk names follow the specifications; section numbers refer to them.
//
// Reading never trusts a length: every chunk length is compared with the bytes left,
// every count with what the stored bytes can hold, before anything is allocated, and
// inflated data grows only as zlib actually produces it, never past the stored raw_size.

#include "lex3d/codec/codec.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>

#include <zlib.h>

#include "codec/bytes.hpp"

namespace lex3d::codec {
namespace {

// ---------------------------------------------------------------------------------------
// Constants of the specifications
// ---------------------------------------------------------------------------------------

constexpr char kModelMagic[8] = {'L', 'E', 'X', '3', 'D', 'M', 'D', 'L'};
constexpr char kAlphabetMagic[8] = {'L', 'E', 'X', '3', 'D', 'A', 'L', 'P'};
constexpr char kSequenceMagic[8] = {'L', 'E', 'X', '3', 'D', 'S', 'E', 'Q'};
constexpr std::uint64_t kQhdrBytes = 8;
constexpr std::size_t kMaxScanNameBytes = 255;  // sequence.md §2
constexpr std::uint16_t kMajor = 1;
constexpr std::uint16_t kMinor = 0;        // written for files without a residual layer
/// The chunk of a residual layer by its coding (layer_coding), with the first minor
/// version that has it: RESD 1.1, RESW 1.2, RESV 1.3, RESL 1.4, RESA and RESG 1.12.
struct LayerChunk {
  const char* type;
  std::uint16_t minor;
  const char* coding;
};
constexpr LayerChunk kLayerChunks[] = {
    {"RESD", 1, "previous-point"}, {"RESW", 2, "sweep"}, {"RESV", 3, "voxel"}, {"RESL", 4, "sensor-geometry"},
    {"RESA", 12, "acquisition-order"}, {"RESG", 12, "lattice"}};
constexpr std::uint32_t kLayerCodings = 6;
/// A sensor-geometry layer whose range predictor is 2 or 3 (edge flags, model.md §2.8.2)
/// and the first minor version that has it.
constexpr std::uint16_t kLaserEdgeMinor = 7;
constexpr std::size_t kLaserPredictorOffset = 68;
/// A sensor-geometry layer whose range residuals are coded with mixed contexts (range
/// predictor 4 or 5, model.md §2.8.4) and the first minor version that has it.
constexpr std::uint16_t kLaserMixedMinor = 9;
/// A voxel layer with the mixed octree contexts (model.md §2.7.4) and the first minor
/// version that has it.
constexpr std::uint16_t kVoxelMixedMinor = 8;
constexpr std::size_t kVoxelContextsOffset = 65;
/// The georeference chunk and the first minor version that has it (model.md §2.9).
constexpr char kGeorType[] = "GEOR";
constexpr std::uint16_t kGeorMinor = 5;
constexpr std::uint64_t kGeorFixedBytes = 96;
/// The scan's stamp and frame (model.md §2.13): an optional chunk, so no format version.
constexpr char kScanType[] = "scan";
constexpr std::size_t kScanHeadBytes = 15;     // source u8, sec u64, nsec u32, frame length u16
constexpr std::size_t kMaxFrameIdBytes = 1024;
/// The point attributes chunk and the first minor version that has it (model.md §2.10).
constexpr char kAttrType[] = "ATTR";
constexpr std::uint16_t kAttrMinor = 6;
/// An ATTR chunk holding a named integer field (kind 5) or colour coded as differences
/// (rgb `transform` 1) and the first minor version that has them (model.md §2.10).
constexpr std::uint16_t kAttrExtendedMinor = 10;
/// An ATTR chunk whose named field records its source type (kind 5 with a `transform`, a
/// FieldType; floating-point fields) and the first minor version that has it (model.md §2.10).
constexpr std::uint16_t kAttrTypedMinor = 15;
/// An ATTR chunk whose ring, intensity or time records the name and type its source stored
/// it in (kinds 1-3 with a `transform`, the name after the descriptor) and the first minor
/// version that has it (model.md §2.10).
constexpr std::uint16_t kAttrSourceMinor = 16;
/// An ATTR field coded against the measurement columns of the sensor-geometry layer
/// (method 6) and the first minor version that has it (model.md §2.10).
constexpr std::uint16_t kAttrColumnMinor = 17;
/// A model without instances (no INST chunk, the short MHDR) or without words at all (no
/// alphabet: flag bits 0 and 1 clear) and the first minor version that has it (model.md
/// §2.1, §2.4).
constexpr std::uint16_t kNoInstancesMinor = 11;
/// The marker of a sensor-geometry layer whose fields leave out T_sensor_head, the
/// identity (model.md §2.8), and the first minor version that has it.
constexpr std::uint32_t kLaserShortMarker = 0xFFFFFFFEU;
constexpr std::uint16_t kLaserShortMinor = 11;
/// Bit 8 of a sensor-geometry layer's predictor field (its table's fields each coded
/// against its own predictor, model.md §2.8.1) and the first minor version that has it.
constexpr std::uint32_t kLaserTablePredictorsBit = 1U << 8;
constexpr std::uint16_t kLaserTablePredictorsMinor = 11;
/// Bit 9 of a sensor-geometry layer's predictor field (the beams' origins move over the
/// turn, model.md §2.8.5) and the first minor version that has it.
constexpr std::uint32_t kLaserMotionBit = 1U << 9;
constexpr std::uint16_t kLaserMotionMinor = 14;
/// Bit 10 of a sensor-geometry layer's predictor field (predictor 4 or 5's mixed models
/// learn at the quick rates, model.md §2.8.4) and the first minor version that has it.
constexpr std::uint32_t kLaserQuickModelsBit = 1U << 10;
constexpr std::uint16_t kLaserQuickModelsMinor = 18;
/// The first minor version with an acquisition-order layer whose x and y are fitted with a
/// line or whose cells are taller than wide (its prediction field not 0, model.md §2.11),
/// or a lattice layer whose cells' points are stacked (its order field not 0, §2.12).
constexpr std::uint16_t kLayerFieldsMinor = 13;
constexpr std::size_t kAcquisitionFitOffset = 64;
constexpr std::size_t kLatticeOrderOffset = 80;
constexpr double kGeorMaxOrigin = 1e9;                        // metres
constexpr double kGeorMinUnit = 1e-3, kGeorMaxUnit = 1e4;     // metres per CRS unit
constexpr std::size_t kGeorMaxString = 4096;
constexpr std::uint32_t kGeorMaxRecords = 256;
constexpr std::uint64_t kGeorMaxRecordBytes = 1U << 20;       // all CRS records together
/// Bit 31 of the GEOR record count: the records are deflated (model.md §2.9, format 1.12).
constexpr std::uint32_t kGeorDeflatedBit = 1U << 31;
constexpr std::uint16_t kGeorDeflatedMinor = 12;
constexpr std::size_t kGeorRecordHead = 16 + 2 + 1 + 32 + 4;  // user_id, record_id, extended, description, length
constexpr std::size_t kHeaderBytes = 20;      // magic 8, major 2, minor 2, flags 4, header_crc 4
constexpr std::size_t kChunkHeadBytes = 12;   // type 4, length 8
constexpr std::size_t kChunkCrcBytes = 4;
constexpr std::uint32_t kFlagAlphabetEmbedded = 1U << 0;
constexpr std::uint32_t kFlagAlphabetReferenced = 1U << 1;
constexpr std::uint64_t kMhdrBytes = 120;
constexpr std::uint64_t kMhdrShortBytes = 8;       // input_points (identity sensor pose)
constexpr std::uint64_t kMhdrShortPoseBytes = 104;  // input_points, T_cloud_sensor
constexpr std::uint64_t kAhdrBytes = 32;
constexpr std::uint64_t kArefBytes = 8;
constexpr std::uint64_t kDeflatedHeadBytes = 16;  // count u64 + raw_size u64 (INST, WORD)
constexpr std::uint64_t kInstanceRawBytes = 28;   // 7 columns of u32
constexpr std::uint32_t kMaxDescriptorDim = 65535;
constexpr std::uint64_t kMaxInflateRatio = 1032;  // deflate's best case is ~1032:1
constexpr std::uint64_t kInflateSlack = 64;
// zlib's default level: on a KITTI model (170 KB of instance columns) 5x faster than
// level 9 (3.8 against 20 ms) for 0.4 % more bytes.
constexpr int kZlibLevel = 6;
constexpr double kOrthonormalTolerance = 1e-6;
constexpr double kDescriptorScale = 127.0;
constexpr double kPi = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------
// Little-endian fields (codec/bytes.hpp)
// ---------------------------------------------------------------------------------------

using bytes::ld_f64;
using bytes::ld_u16;
using bytes::ld_u32;
using bytes::ld_u64;
using bytes::put_f64;
using bytes::put_u16;
using bytes::put_u32;
using bytes::put_u64;

std::uint32_t zigzag(std::int32_t x) {
  const auto u = static_cast<std::uint32_t>(x);
  return (u << 1) ^ (x < 0 ? 0xFFFFFFFFU : 0U);
}
std::int32_t unzigzag(std::uint32_t u) {
  const std::uint32_t v = (u >> 1) ^ (0U - (u & 1U));
  std::int32_t x = 0;
  std::memcpy(&x, &v, sizeof x);  // two's complement reinterpretation, no UB
  return x;
}
std::int32_t as_i32(std::uint32_t u) {
  std::int32_t x = 0;
  std::memcpy(&x, &u, sizeof x);
  return x;
}

/// planes(v): byte k·n + i is byte k of v[i] (formats/alphabet.md §1).
void put_planes(std::vector<std::uint8_t>& raw, const std::vector<std::uint32_t>& v) {
  const std::size_t n = v.size();
  const std::size_t at = raw.size();
  raw.resize(at + 4 * n);
  for (std::size_t k = 0; k < 4; ++k)
    for (std::size_t i = 0; i < n; ++i)
      raw[at + k * n + i] = static_cast<std::uint8_t>((v[i] >> (8 * k)) & 0xFFU);
}

std::uint32_t crc_of(const std::uint8_t* data, std::size_t n, std::uint32_t crc = 0) {
  uLong c = crc;
  while (n > 0) {
    const std::size_t step = std::min<std::size_t>(n, 1U << 30);
    c = crc32(c, data, static_cast<uInt>(step));
    data += step;
    n -= step;
  }
  return static_cast<std::uint32_t>(c);
}

void put_header(std::vector<std::uint8_t>& out, const char (&magic)[8], std::uint32_t flags,
                std::uint16_t minor = kMinor) {
  out.insert(out.end(), magic, magic + 8);
  put_u16(out, kMajor);
  put_u16(out, minor);
  put_u32(out, flags);
  put_u32(out, crc_of(out.data() + out.size() - 16, 16));
}

/// type(4) length(u64) payload crc(u32 of type ‖ length ‖ payload).
void put_chunk(std::vector<std::uint8_t>& out, const char* type, const std::vector<std::uint8_t>& payload) {
  const std::size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  put_u64(out, payload.size());
  out.insert(out.end(), payload.begin(), payload.end());
  put_u32(out, crc_of(out.data() + start, out.size() - start));
}

/// The zlib stream of `raw` at kZlibLevel (deterministic for a zlib build).
std::vector<std::uint8_t> deflated(const std::vector<std::uint8_t>& raw) {
  uLongf bound = compressBound(static_cast<uLong>(raw.size()));
  std::vector<std::uint8_t> z(bound);
  if (compress2(z.data(), &bound, raw.data(), static_cast<uLong>(raw.size()), kZlibLevel) != Z_OK)
    throw std::runtime_error("lex3d::codec: zlib compress2 failed");
  z.resize(bound);
  return z;
}

/// count u64, raw_size u64, deflated(raw).
std::vector<std::uint8_t> deflated_payload(std::uint64_t count, const std::vector<std::uint8_t>& raw) {
  std::vector<std::uint8_t> p;
  put_u64(p, count);
  put_u64(p, raw.size());
  const std::vector<std::uint8_t> z = deflated(raw);
  p.insert(p.end(), z.begin(), z.end());
  return p;
}

std::int32_t quantize(double value, double step, const char* what) {
  const double x = value / step;
  if (!std::isfinite(x) || std::abs(x) > 2147483647.0)
    throw std::invalid_argument(std::string("lex3d::codec: ") + what + " " + std::to_string(value) +
                                " does not fit an i32 in units of " + std::to_string(step));
  return static_cast<std::int32_t>(std::llround(x));
}

bool orthonormal(const Eigen::Matrix3d& R) {
  return R.allFinite() && (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <= kOrthonormalTolerance &&
         R.determinant() > 0.0;
}

// ---------------------------------------------------------------------------------------
// Reading: context for errors, little-endian loads, the container
// ---------------------------------------------------------------------------------------

/// Where a byte string sits and what to call it in messages. `base` is the offset of
/// byte 0 in the file the user gave (non-zero for an embedded alphabet).
struct Ctx {
  std::string what;
  std::uint64_t base = 0;
  [[nodiscard]] Status error(const std::string& message, std::uint64_t offset) const {
    return bad_data(what + ": " + message, base + offset);
  }
};

/// Element i of a planes() column of n values starting at `col`.
std::uint32_t ld_plane(const std::uint8_t* col, std::size_t n, std::size_t i) {
  return static_cast<std::uint32_t>(col[i]) | (static_cast<std::uint32_t>(col[n + i]) << 8) |
         (static_cast<std::uint32_t>(col[2 * n + i]) << 16) | (static_cast<std::uint32_t>(col[3 * n + i]) << 24);
}

std::string hex(std::uint64_t v, int digits) {
  static const char* kDigits = "0123456789abcdef";
  std::string s(static_cast<std::size_t>(digits), '0');
  for (int i = digits - 1; i >= 0; --i, v >>= 4) s[static_cast<std::size_t>(i)] = kDigits[v & 0xFU];
  return "0x" + s;
}

/// A chunk type for messages: letters as they are, anything else as \xNN (one line).
std::string printable_type(const std::uint8_t* t) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const std::uint8_t c = t[i];
    if (c >= 0x20 && c < 0x7F && c != '\\' && c != '\'') {
      s.push_back(static_cast<char>(c));
    } else {
      s += "\\x" + hex(c, 2).substr(2);
    }
  }
  return "'" + s + "'";
}

bool is_letter(std::uint8_t c) { return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z'); }

struct Header {
  std::uint16_t major = 0;
  std::uint16_t minor = 0;
  std::uint32_t flags = 0;
  bool crc_ok = false;
};

/// Checks magic, major version (and, when `strict`, the header CRC): alphabet.md §2.
Status read_header(const std::uint8_t* d, std::size_t size, const Ctx& ctx, const char (&magic)[8],
                   const char (&other_magic)[8], const char* other_kind, bool strict, Header& h) {
  const std::size_t have = std::min<std::size_t>(size, 8);
  if (have > 0 && std::memcmp(d, magic, have) != 0) {  // d may be null when size is 0
    if (size >= 8 && std::memcmp(d, other_magic, 8) == 0)
      return ctx.error(std::string("this is a lex3d ") + other_kind + " file", 0);
    return ctx.error("bad magic (expected \"" + std::string(magic, 8) + "\")", 0);
  }
  if (size < 12) return ctx.error("truncated header (" + std::to_string(size) + " of 20 bytes)", size);
  h.major = ld_u16(d + 8);
  h.minor = ld_u16(d + 10);
  if (h.major != kMajor)
    return ctx.error("unsupported format version " + std::to_string(h.major) + "." + std::to_string(h.minor) +
                         " (this reader reads major version 1)",
                     8);
  if (size < kHeaderBytes) return ctx.error("truncated header (" + std::to_string(size) + " of 20 bytes)", size);
  h.flags = ld_u32(d + 12);
  const std::uint32_t stored = ld_u32(d + 16);
  const std::uint32_t computed = crc_of(d, 16);
  h.crc_ok = stored == computed;
  if (strict && !h.crc_ok)
    return ctx.error("header CRC mismatch (stored " + hex(stored, 8) + ", computed " + hex(computed, 8) + ")", 16);
  return {};
}

struct Chunk {
  const std::uint8_t* type = nullptr;  // 4 bytes
  std::string name;                    // printable, quoted
  std::uint64_t offset = 0;            // of the chunk header, relative to the byte string
  const std::uint8_t* payload = nullptr;
  std::uint64_t length = 0;
  std::uint64_t payload_offset = 0;
  std::uint32_t stored_crc = 0;
  std::uint32_t computed_crc = 0;
  [[nodiscard]] bool is(const char* t) const { return std::memcmp(type, t, 4) == 0; }
  [[nodiscard]] bool required() const { return type[0] >= 'A' && type[0] <= 'Z'; }
};

/// Frames one chunk at `pos`: the length is checked against the bytes left before
/// anything else; the CRC is computed (not judged) here.
Status frame_chunk(const std::uint8_t* d, std::size_t size, std::size_t pos, const Ctx& ctx, Chunk& c) {
  const std::size_t left = size - pos;
  if (left < kChunkHeadBytes)
    return ctx.error("truncated chunk header (" + std::to_string(left) + " of 12 bytes)", pos);
  c.type = d + pos;
  c.name = printable_type(c.type);
  c.offset = pos;
  c.length = ld_u64(d + pos + 4);
  const std::uint64_t room = left - kChunkHeadBytes;
  if (room < kChunkCrcBytes || c.length > room - kChunkCrcBytes)
    return ctx.error("chunk " + c.name + " length " + std::to_string(c.length) + " exceeds the " +
                         std::to_string(room < kChunkCrcBytes ? 0 : room - kChunkCrcBytes) + " bytes left",
                     pos + 4);
  const auto len = static_cast<std::size_t>(c.length);
  c.payload = d + pos + kChunkHeadBytes;
  c.payload_offset = pos + kChunkHeadBytes;
  c.stored_crc = ld_u32(c.payload + len);
  c.computed_crc = crc_of(d + pos, kChunkHeadBytes + len);
  return {};
}

/// Frames the chunk at `pos` and checks its type letters and its CRC (alphabet.md §2).
Status read_chunk(const std::uint8_t* d, std::size_t size, std::size_t pos, const Ctx& ctx, Chunk& c) {
  if (Status s = frame_chunk(d, size, pos, ctx, c); !s.ok()) return s;
  if (!(is_letter(c.type[0]) && is_letter(c.type[1]) && is_letter(c.type[2]) && is_letter(c.type[3])))
    return ctx.error("invalid chunk type " + c.name + " (4 ASCII letters expected)", pos);
  if (c.stored_crc != c.computed_crc)
    return ctx.error("chunk " + c.name + " CRC mismatch (stored " + hex(c.stored_crc, 8) + ", computed " +
                         hex(c.computed_crc, 8) + ")",
                     c.payload_offset + c.length);
  return {};
}

/// Whether a well-framed chunk of `type` appears among the chunks after the header
/// (framing errors end the scan; walk_chunks reports them).
bool has_chunk(const std::uint8_t* d, std::size_t size, const char* type) {
  const Ctx ctx{"", 0};
  for (std::size_t pos = kHeaderBytes; pos < size;) {
    Chunk c;
    if (!frame_chunk(d, size, pos, ctx, c).ok()) return false;
    if (c.is(type)) return true;
    pos = static_cast<std::size_t>(c.payload_offset + c.length + kChunkCrcBytes);
  }
  return false;
}

/// Walks the chunks of a file: framing, type letters, CRC, known/unknown, order and the
/// end chunk (alphabet.md §2). `sequence` lists the known chunks this file must hold, in
/// order (the first and the last are the first and end chunks); `known` lists every
/// chunk type of the format (a known type missing from `sequence` is out of place).
/// `on_chunk(index in sequence, chunk)` decodes a payload.
/// `on_optional(chunk)`, where given, sees every optional chunk this walk does not know.
template <typename OnChunk>
Status walk_chunks(const std::uint8_t* d, std::size_t size, const Ctx& ctx, const std::vector<const char*>& sequence,
                   const std::vector<const char*>& known, OnChunk&& on_chunk,
                   const std::function<Status(const Chunk&)>& on_optional = {}) {
  std::size_t pos = kHeaderBytes;
  std::size_t next = 0;  // index in `sequence` of the next expected known chunk
  for (;;) {
    if (pos == size)
      return ctx.error("file ends before the '" + std::string(sequence.back(), 4) + "' chunk", pos);
    Chunk c;
    if (Status s = read_chunk(d, size, pos, ctx, c); !s.ok()) return s;
    const auto in_seq = std::find_if(sequence.begin(), sequence.end(), [&](const char* t) { return c.is(t); });
    const bool is_known = std::any_of(known.begin(), known.end(), [&](const char* t) { return c.is(t); });
    if (next == 0 && in_seq != sequence.begin())
      return ctx.error("the first chunk must be '" + std::string(sequence.front(), 4) + "', found " + c.name, pos);
    if (in_seq == sequence.end()) {
      if (is_known) return ctx.error("chunk " + c.name + " does not belong in this file (see its flags)", pos);
      if (c.required()) return ctx.error("unknown required chunk " + c.name, pos);
      if (on_optional)
        if (Status s = on_optional(c); !s.ok()) return s;
      pos = static_cast<std::size_t>(c.payload_offset + c.length + kChunkCrcBytes);  // unknown optional: skip
      continue;
    }
    const auto index = static_cast<std::size_t>(in_seq - sequence.begin());
    if (index < next) return ctx.error("chunk " + c.name + " is repeated or out of order", pos);
    if (index > next)
      return ctx.error("chunk " + c.name + " comes before the required chunk '" + std::string(sequence[next], 4) + "'",
                       pos);
    if (Status s = on_chunk(index, c); !s.ok()) return s;
    ++next;
    pos = static_cast<std::size_t>(c.payload_offset + c.length + kChunkCrcBytes);
    if (index + 1 == sequence.size()) {  // the end chunk
      if (c.length != 0)
        return ctx.error("end chunk " + c.name + " must be empty, has " + std::to_string(c.length) + " bytes",
                         c.offset + 4);
      if (pos != size)
        return ctx.error(std::to_string(size - pos) + " bytes after the end chunk " + c.name, pos);
      return {};
    }
  }
}

Status expect_length(const Chunk& c, std::uint64_t want, const Ctx& ctx) {
  if (c.length != want)
    return ctx.error("chunk " + c.name + " payload is " + std::to_string(c.length) + " bytes, expected " +
                         std::to_string(want),
                     c.offset + 4);
  return {};
}

/// Inflates a zlib stream into exactly `raw_size` bytes (alphabet.md §5). `offset` is
/// that of the stream, for messages. The output grows with what zlib produces.
Status inflate_exact(const std::uint8_t* src, std::uint64_t src_len, std::uint64_t raw_size, const Ctx& ctx,
                     const std::string& chunk, std::uint64_t offset, std::vector<std::uint8_t>& out) {
  constexpr std::size_t kSlice = std::size_t{1} << 30;
  z_stream zs{};
  if (inflateInit(&zs) != Z_OK) return ctx.error("zlib could not start inflating chunk " + chunk, offset);
  struct End {
    z_stream* z;
    ~End() { inflateEnd(z); }
  } end{&zs};
  out.clear();
  out.resize(static_cast<std::size_t>(std::min<std::uint64_t>(raw_size, (std::uint64_t{1} << 16) + 4 * src_len)));
  std::size_t produced = 0;
  std::uint64_t fed = 0;
  for (;;) {
    if (zs.avail_in == 0 && fed < src_len) {
      const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(src_len - fed, kSlice));
      zs.next_in = const_cast<Bytef*>(src + fed);  // zlib's API is not const-correct; it does not write
      zs.avail_in = static_cast<uInt>(n);
      fed += n;
    }
    std::uint8_t probe = 0;
    bool probing = false;
    if (produced == out.size()) {
      if (out.size() < raw_size)
        out.resize(static_cast<std::size_t>(std::min<std::uint64_t>(raw_size, std::max<std::uint64_t>(2 * out.size(), 1U << 16))));
      else
        probing = true;  // all raw_size bytes are in: any further output is an error
    }
    if (probing) {
      zs.next_out = &probe;
      zs.avail_out = 1;
    } else {
      zs.next_out = out.data() + produced;
      zs.avail_out = static_cast<uInt>(std::min(out.size() - produced, kSlice));
    }
    const uInt before = zs.avail_out;
    const int ret = inflate(&zs, Z_NO_FLUSH);
    const uInt got = before - zs.avail_out;
    const std::uint64_t at = offset + (fed - zs.avail_in);
    if (probing && got > 0)
      return ctx.error("chunk " + chunk + " inflates to more than its raw_size of " + std::to_string(raw_size) + " bytes",
                       at);
    if (!probing) produced += got;
    if (ret == Z_STREAM_END) break;
    if (ret == Z_OK) continue;
    if (ret == Z_BUF_ERROR && !(zs.avail_in == 0 && fed == src_len)) continue;
    if (ret == Z_BUF_ERROR) return ctx.error("chunk " + chunk + " deflate stream is truncated", at);
    return ctx.error("chunk " + chunk + " deflate stream is corrupt (" + std::string(zs.msg ? zs.msg : "zlib error") + ")",
                     at);
  }
  if (produced != raw_size)
    return ctx.error("chunk " + chunk + " inflates to " + std::to_string(produced) + " bytes, its raw_size says " +
                         std::to_string(raw_size),
                     offset);
  const std::uint64_t rest = zs.avail_in + (src_len - fed);
  if (rest != 0)
    return ctx.error(std::to_string(rest) + " bytes after the deflate stream in chunk " + chunk, offset + src_len - rest);
  out.resize(produced);
  return {};
}

/// raw_size must not exceed what deflate can produce from `stored` bytes.
bool inflatable(std::uint64_t raw_size, std::uint64_t stored) {
  const std::uint64_t cap = stored > (std::numeric_limits<std::uint64_t>::max() - kInflateSlack) / kMaxInflateRatio
                                ? std::numeric_limits<std::uint64_t>::max()
                                : stored * kMaxInflateRatio + kInflateSlack;
  return raw_size <= cap;
}

// ---------------------------------------------------------------------------------------
// Alphabet file (alphabet.md §3)
// ---------------------------------------------------------------------------------------

void check_alphabet(const Alphabet& a) {
  const auto fail = [](const std::string& m) { throw std::invalid_argument("lex3d::codec::encode_alphabet: " + m); };
  if (!(std::isfinite(a.word_radius) && a.word_radius >= 0.0)) fail("word_radius must be finite and >= 0");
  if (!(std::isfinite(a.point_spacing) && a.point_spacing >= 0.0)) fail("point_spacing must be finite and >= 0");
  if (a.descriptor_dim < 0 || static_cast<std::uint32_t>(a.descriptor_dim) > kMaxDescriptorDim)
    fail("descriptor_dim must be in [0, 65535]");
  if (a.words.size() > std::numeric_limits<std::uint32_t>::max()) fail("more than 2^32 - 1 words");
  for (std::size_t w = 0; w < a.words.size(); ++w) {
    const Word& word = a.words[w];
    if (word.descriptor.size() != static_cast<std::size_t>(a.descriptor_dim))
      fail("word " + std::to_string(w) + " has " + std::to_string(word.descriptor.size()) +
           " descriptor values, descriptor_dim is " + std::to_string(a.descriptor_dim));
    if (word.points.size() > std::numeric_limits<std::uint32_t>::max()) fail("a word has more than 2^32 - 1 points");
    for (const float d : word.descriptor)
      if (!(d >= -1.0F && d <= 1.0F)) fail("word " + std::to_string(w) + " has a descriptor value outside [-1, 1]");
  }
}

struct AhdrFields {
  double word_radius = 0.0;
  double point_spacing = 0.0;
  std::uint32_t descriptor_dim = 0;
  std::uint32_t word_count = 0;
  double word_point_m = 0.0;
};

Status read_ahdr(const Chunk& c, const Ctx& ctx, AhdrFields& h) {
  if (Status s = expect_length(c, kAhdrBytes, ctx); !s.ok()) return s;
  const std::uint8_t* p = c.payload;
  h.word_radius = ld_f64(p);
  h.point_spacing = ld_f64(p + 8);
  h.descriptor_dim = ld_u32(p + 16);
  h.word_count = ld_u32(p + 20);
  h.word_point_m = ld_f64(p + 24);
  if (!(std::isfinite(h.word_radius) && h.word_radius >= 0.0))
    return ctx.error("AHDR word_radius " + std::to_string(h.word_radius) + " is not finite and >= 0", c.payload_offset);
  if (!(std::isfinite(h.point_spacing) && h.point_spacing >= 0.0))
    return ctx.error("AHDR point_spacing " + std::to_string(h.point_spacing) + " is not finite and >= 0",
                     c.payload_offset + 8);
  if (h.descriptor_dim > kMaxDescriptorDim)
    return ctx.error("AHDR descriptor_dim " + std::to_string(h.descriptor_dim) + " exceeds 65535", c.payload_offset + 16);
  if (!(h.word_point_m > 0.0 && h.word_point_m <= 0.1))
    return ctx.error("AHDR word_point_m " + std::to_string(h.word_point_m) + " is outside (0, 0.1]",
                     c.payload_offset + 24);
  return {};
}

Status read_word(const Chunk& c, const Ctx& ctx, const AhdrFields& h, Alphabet& a) {
  if (c.length < kDeflatedHeadBytes)
    return ctx.error("chunk 'WORD' payload is " + std::to_string(c.length) + " bytes, at least 16 expected",
                     c.offset + 4);
  const std::uint64_t total_points = ld_u64(c.payload);
  const std::uint64_t raw_size = ld_u64(c.payload + 8);
  if (total_points > (std::uint64_t{1} << 58))
    return ctx.error("WORD total_points " + std::to_string(total_points) + " is absurd", c.payload_offset);
  const std::uint64_t W = h.word_count;
  const std::uint64_t expected = 4 * W + 12 * total_points + W * h.descriptor_dim;
  if (raw_size != expected)
    return ctx.error("WORD raw_size " + std::to_string(raw_size) + " is not 4*word_count + 12*total_points + " +
                         "word_count*descriptor_dim = " + std::to_string(expected),
                     c.payload_offset + 8);
  const std::uint64_t stored = c.length - kDeflatedHeadBytes;
  if (!inflatable(raw_size, stored))
    return ctx.error("WORD raw_size " + std::to_string(raw_size) + " cannot come from " + std::to_string(stored) +
                         " deflated bytes",
                     c.payload_offset + 8);
  std::vector<std::uint8_t> raw;
  if (Status s = inflate_exact(c.payload + kDeflatedHeadBytes, stored, raw_size, ctx, "'WORD'",
                               c.payload_offset + kDeflatedHeadBytes, raw);
      !s.ok())
    return s;
  // raw_size == expected and the data are in memory, so every count below is backed by bytes.
  const auto n_words = static_cast<std::size_t>(W);
  const auto n_points = static_cast<std::size_t>(total_points);
  const std::uint8_t* counts = raw.data();
  std::uint64_t sum = 0;
  for (std::size_t w = 0; w < n_words; ++w) sum += ld_plane(counts, n_words, w);
  if (sum != total_points)
    return ctx.error("WORD point counts add up to " + std::to_string(sum) + ", total_points is " +
                         std::to_string(total_points),
                     c.payload_offset);
  const std::uint8_t* xs = counts + 4 * n_words;
  const std::uint8_t* ys = xs + 4 * n_points;
  const std::uint8_t* zs = ys + 4 * n_points;
  const auto* desc = zs + 4 * n_points;
  const std::size_t dim = h.descriptor_dim;
  a.word_radius = h.word_radius;
  a.point_spacing = h.point_spacing;
  a.descriptor_dim = static_cast<int>(h.descriptor_dim);
  a.words.assign(n_words, Word{});
  std::size_t k = 0;
  for (std::size_t w = 0; w < n_words; ++w) {
    Word& word = a.words[w];
    const std::uint32_t count = ld_plane(counts, n_words, w);
    word.points.resize(count);
    for (auto& p : word.points) {
      p = Eigen::Vector3f(static_cast<float>(unzigzag(ld_plane(xs, n_points, k)) * h.word_point_m),
                          static_cast<float>(unzigzag(ld_plane(ys, n_points, k)) * h.word_point_m),
                          static_cast<float>(unzigzag(ld_plane(zs, n_points, k)) * h.word_point_m));
      ++k;
    }
    word.descriptor.resize(dim);
    for (std::size_t j = 0; j < dim; ++j) {
      const auto q = static_cast<std::int8_t>(desc[w * dim + j]);
      if (q == -128)
        return ctx.error("WORD descriptor value -128 of word " + std::to_string(w) + " is outside [-127, 127]",
                         c.payload_offset + kDeflatedHeadBytes);
      word.descriptor[j] = static_cast<float>(q / kDescriptorScale);
    }
  }
  return {};
}

StatusOr<Alphabet> decode_alphabet_at(const std::uint8_t* d, std::size_t size, const Ctx& ctx) {
  Header h;
  if (Status s = read_header(d, size, ctx, kAlphabetMagic, kModelMagic, "model", true, h); !s.ok()) return s;
  if (h.flags != 0) return ctx.error("reserved flag bits " + hex(h.flags, 8) + " set", 12);
  AhdrFields ahdr;
  Alphabet a;
  const Status s = walk_chunks(d, size, ctx, {"AHDR", "WORD", "AEND"}, {"AHDR", "WORD", "AEND"},
                               [&](std::size_t index, const Chunk& c) -> Status {
                                 if (index == 0) return read_ahdr(c, ctx, ahdr);
                                 if (index == 1) return read_word(c, ctx, ahdr, a);
                                 return {};
                               });
  if (!s.ok()) return s;
  return a;
}

// ---------------------------------------------------------------------------------------
// Model file (model.md §2)
// ---------------------------------------------------------------------------------------

struct MhdrFields {
  std::uint64_t input_points = 0;
  Pose T_cloud_sensor = Pose::Identity();
  double translation_m = 0.0;
  double rotation_rad = 0.0;
};

/// `with_instances`: the file has an INST chunk, whose steps the full MHDR carries; a
/// file without one (format 1.11) has the short MHDR, 8 bytes, or 104 with a sensor pose.
Status read_mhdr(const Chunk& c, const Ctx& ctx, bool with_instances, MhdrFields& h) {
  if (with_instances) {
    if (Status s = expect_length(c, kMhdrBytes, ctx); !s.ok()) return s;
  } else if (c.length != kMhdrShortBytes && c.length != kMhdrShortPoseBytes) {
    return ctx.error("chunk 'MHDR' payload is " + std::to_string(c.length) +
                         " bytes, expected 8 or 104 in a model file without instances",
                     c.offset + 4);
  }
  const std::uint8_t* p = c.payload;
  h.input_points = ld_u64(p);
  if (c.length == kMhdrShortBytes) return {};
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  for (int i = 0; i < 12; ++i) {
    const double v = ld_f64(p + 8 + 8 * i);
    if (!std::isfinite(v))
      return ctx.error("MHDR T_cloud_sensor value " + std::to_string(i) + " is not finite",
                       c.payload_offset + 8 + 8 * static_cast<std::uint64_t>(i));
    if (i < 9)
      R(i / 3, i % 3) = v;
    else
      t(i - 9) = v;
  }
  if (!orthonormal(R)) return ctx.error("MHDR T_cloud_sensor rotation is not orthonormal", c.payload_offset + 8);
  h.T_cloud_sensor = Pose::Identity();
  h.T_cloud_sensor.linear() = R;
  h.T_cloud_sensor.translation() = t;
  if (!with_instances) return {};
  h.translation_m = ld_f64(p + 104);
  h.rotation_rad = ld_f64(p + 112);
  if (!(h.translation_m > 0.0 && h.translation_m <= 0.1))
    return ctx.error("MHDR translation_m " + std::to_string(h.translation_m) + " is outside (0, 0.1]",
                     c.payload_offset + 104);
  if (!(h.rotation_rad > 0.0 && h.rotation_rad <= 0.1))
    return ctx.error("MHDR rotation_rad " + std::to_string(h.rotation_rad) + " is outside (0, 0.1]",
                     c.payload_offset + 112);
  return {};
}

Status read_inst(const Chunk& c, const Ctx& ctx, const MhdrFields& h, std::size_t alphabet_words, Model& model) {
  if (c.length < kDeflatedHeadBytes)
    return ctx.error("chunk 'INST' payload is " + std::to_string(c.length) + " bytes, at least 16 expected",
                     c.offset + 4);
  const std::uint64_t instance_count = ld_u64(c.payload);
  const std::uint64_t raw_size = ld_u64(c.payload + 8);
  const std::uint64_t stored = c.length - kDeflatedHeadBytes;
  if (instance_count > std::numeric_limits<std::uint64_t>::max() / kInstanceRawBytes ||
      !inflatable(instance_count * kInstanceRawBytes, stored))
    return ctx.error("INST instance_count " + std::to_string(instance_count) + " cannot come from " +
                         std::to_string(stored) + " deflated bytes",
                     c.payload_offset);
  if (raw_size != instance_count * kInstanceRawBytes)
    return ctx.error("INST raw_size " + std::to_string(raw_size) + " is not 28*instance_count = " +
                         std::to_string(instance_count * kInstanceRawBytes),
                     c.payload_offset + 8);
  std::vector<std::uint8_t> raw;
  const std::uint64_t data_offset = c.payload_offset + kDeflatedHeadBytes;
  if (Status s = inflate_exact(c.payload + kDeflatedHeadBytes, stored, raw_size, ctx, "'INST'", data_offset, raw);
      !s.ok())
    return s;
  const auto n = static_cast<std::size_t>(instance_count);
  const std::uint8_t* col[7];
  for (std::size_t k = 0; k < 7; ++k) col[k] = raw.data() + 4 * n * k;
  model.instances.assign(n, Instance{});
  const double max_angle = kPi + h.rotation_rad;
  std::uint32_t tq[3] = {0, 0, 0};  // previous quantised translation, modulo 2^32
  for (std::size_t i = 0; i < n; ++i) {
    Instance& inst = model.instances[i];
    inst.word = ld_plane(col[0], n, i);
    if (inst.word >= alphabet_words)
      return ctx.error("instance " + std::to_string(i) + " has word id " + std::to_string(inst.word) +
                           " but the alphabet has " + std::to_string(alphabet_words) + " words",
                       data_offset);
    Eigen::Vector3d t;
    Eigen::Vector3d r;
    for (int a = 0; a < 3; ++a) {
      const auto ua = static_cast<std::size_t>(a);
      tq[ua] += static_cast<std::uint32_t>(unzigzag(ld_plane(col[1 + ua], n, i)));
      t(a) = as_i32(tq[ua]) * h.translation_m;
      r(a) = unzigzag(ld_plane(col[4 + ua], n, i)) * h.rotation_rad;
    }
    const double angle = r.norm();
    if (angle > max_angle)
      return ctx.error("instance " + std::to_string(i) + " rotation vector is longer than pi (" +
                           std::to_string(angle) + " rad)",
                       data_offset);
    inst.T_cloud_word = Pose::Identity();
    if (angle > 0.0) inst.T_cloud_word.linear() = Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
    inst.T_cloud_word.translation() = t;
    inst.feature = 0;
  }
  return {};
}

std::vector<std::uint8_t> inst_payload(const Model& model, const Quantization& q) {
  const std::size_t n = model.instances.size();
  std::vector<std::uint32_t> cols[7];
  for (auto& c : cols) c.resize(n);
  std::uint32_t prev[3] = {0, 0, 0};
  for (std::size_t i = 0; i < n; ++i) {
    const Instance& inst = model.instances[i];
    const Eigen::Matrix3d R = inst.T_cloud_word.linear();
    const Eigen::Vector3d t = inst.T_cloud_word.translation();
    if (!t.allFinite() || !orthonormal(R))
      throw std::invalid_argument("lex3d::codec::encode_model: instance " + std::to_string(i) +
                                  " pose is not a finite rigid transform");
    const Eigen::AngleAxisd aa(R);  // angle in [0, pi]
    const Eigen::Vector3d r = aa.angle() * aa.axis();
    cols[0][i] = inst.word;
    for (std::size_t a = 0; a < 3; ++a) {
      const auto tq = static_cast<std::uint32_t>(quantize(t(static_cast<int>(a)), q.translation_m, "instance translation"));
      cols[1 + a][i] = zigzag(as_i32(tq - prev[a]));  // difference modulo 2^32
      prev[a] = tq;
      cols[4 + a][i] = zigzag(quantize(r(static_cast<int>(a)), q.rotation_rad, "instance rotation"));
    }
  }
  std::vector<std::uint8_t> raw;
  raw.reserve(kInstanceRawBytes * n);
  for (const auto& c : cols) put_planes(raw, c);
  return deflated_payload(n, raw);
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------------------

void Quantization::validate() const {
  const auto check = [](double v, const char* name) {
    if (!(v > 0.0 && v <= 0.1))
      throw std::invalid_argument(std::string("Quantization::") + name + " must be in (0, 0.1], got " +
                                  std::to_string(v));
  };
  check(translation_m, "translation_m");
  check(rotation_rad, "rotation_rad");
  check(word_point_m, "word_point_m");
}

std::uint32_t layer_coding(const std::vector<std::uint8_t>& payload) {
  // coding u32, then the marker 0xFFFFFFFF (or, after coding 3, 0xFFFFFFFE: the
  // sensor-geometry fields without T_sensor_head), which as the high half of a RESD
  // payload's first field (max_error f64) would make it a NaN.
  if (payload.size() < 8) return 0U;
  const std::uint32_t coding = ld_u32(payload.data()), marker = ld_u32(payload.data() + 4);
  return marker == 0xFFFFFFFFU || (marker == kLaserShortMarker && coding == 3) ? coding : 0U;
}

namespace {
/// Whether a layer is a sensor-geometry one without T_sensor_head (model.md §2.8, 1.11).
bool laser_short_layer(const std::vector<std::uint8_t>& payload) {
  return payload.size() >= 8 && ld_u32(payload.data() + 4) == kLaserShortMarker && ld_u32(payload.data()) == 3;
}
}  // namespace

bool is_sweep_layer(const std::vector<std::uint8_t>& payload) { return layer_coding(payload) == 1; }

/// The minor version a sensor-geometry layer's range predictor needs: 7 for edge flags
/// (predictor 2 or 3), 9 for mixed contexts (4 or 5), 11, 14 or 18 for bit 8, 9 or 10 of its
/// field; 0 for other layers and predictors.
std::uint16_t laser_predictor_minor(const std::vector<std::uint8_t>& payload) {
  if (layer_coding(payload) != 3 || payload.size() < kLaserPredictorOffset + 4) return 0;
  const std::uint32_t field = ld_u32(payload.data() + kLaserPredictorOffset);
  if ((field & kLaserQuickModelsBit) != 0) return kLaserQuickModelsMinor;
  if ((field & kLaserMotionBit) != 0) return kLaserMotionMinor;
  if ((field & kLaserTablePredictorsBit) != 0) return kLaserTablePredictorsMinor;
  const std::uint32_t predictor = field & 0xFFU;
  return predictor >= 4 ? kLaserMixedMinor : predictor >= 2 ? kLaserEdgeMinor : 0;
}

/// The minor version an ATTR payload needs: kAttrExtendedMinor for a named field (kind 5)
/// or colour coded as differences (kind 4 with a transform), kAttrTypedMinor for a named
/// field with its type (kind 5 with a transform), kAttrSourceMinor for a ring, intensity or
/// time with its source's name and type (kinds 1-3 with a transform), kAttrColumnMinor for a
/// field coded with method 6, else kAttrMinor; its descriptors walked
/// as far as they go (the attribute decoder checks them).
std::uint16_t attributes_minor(const std::uint8_t* p, std::uint64_t size) {
  constexpr std::uint64_t kDescriptor = 56;
  std::uint16_t minor = kAttrMinor;
  if (size < 9) return minor;
  std::uint64_t at = 9;
  for (int i = 0; i < p[8] && size - at >= kDescriptor; ++i) {
    const std::uint32_t transform = ld_u32(p + at + 4);
    const bool sourced = p[at] >= 1 && p[at] <= 3 && transform != 0;
    if (p[at] == 5) minor = std::max(minor, transform != 0 ? kAttrTypedMinor : kAttrExtendedMinor);
    if (p[at] == 4 && transform != 0) minor = std::max(minor, kAttrExtendedMinor);
    if (sourced) minor = std::max(minor, kAttrSourceMinor);
    if (p[at + 2] == 6) minor = std::max(minor, kAttrColumnMinor);
    std::uint64_t stream = ld_u64(p + at + 48);
    if (p[at] == 5 || sourced) {  // (its name follows the descriptor: a length byte, then the name)
      if (size - at - kDescriptor < 1) break;
      stream += 1U + p[at + kDescriptor];
    }
    if (stream > size - at - kDescriptor) break;
    at += kDescriptor + stream;
  }
  return minor;
}

/// Where a layer holds a field that format 1.13 added, not 0 (an acquisition-order layer's
/// prediction field, a lattice layer's order field): its offset; else 0.
std::size_t layer_1_13_field(const std::vector<std::uint8_t>& payload) {
  const std::uint32_t coding = layer_coding(payload);
  const std::size_t at = coding == 4 ? kAcquisitionFitOffset : coding == 5 ? kLatticeOrderOffset : 0;
  return at != 0 && payload.size() >= at + 4 && ld_u32(payload.data() + at) != 0 ? at : 0;
}

bool voxel_mixed_layer(const std::vector<std::uint8_t>& payload) {
  return layer_coding(payload) == 2 && payload.size() > kVoxelContextsOffset && payload[kVoxelContextsOffset] >= 1;
}

Quantization quantization_for_word_radius(double word_radius) {
  Quantization q;
  q.word_point_m = 0.0005;
  if (!(word_radius > 0.0) || !std::isfinite(word_radius)) {
    q.translation_m = 0.002;
    q.rotation_rad = 0.001;
    return q;
  }
  q.translation_m = std::min(0.1, word_radius / 32.0);
  q.rotation_rad = 1.0 / 32.0;
  return q;
}

std::vector<std::uint8_t> encode_alphabet(const Alphabet& alphabet, const Quantization& q) {
  q.validate();
  check_alphabet(alphabet);
  std::vector<std::uint8_t> out;
  put_header(out, kAlphabetMagic, 0);

  std::vector<std::uint8_t> ahdr;
  put_f64(ahdr, alphabet.word_radius);
  put_f64(ahdr, alphabet.point_spacing);
  put_u32(ahdr, static_cast<std::uint32_t>(alphabet.descriptor_dim));
  put_u32(ahdr, static_cast<std::uint32_t>(alphabet.words.size()));
  put_f64(ahdr, q.word_point_m);
  put_chunk(out, "AHDR", ahdr);

  std::vector<std::uint32_t> counts;
  std::vector<std::uint32_t> xyz[3];
  std::vector<std::uint8_t> desc;
  for (const Word& w : alphabet.words) {
    counts.push_back(static_cast<std::uint32_t>(w.points.size()));
    for (const auto& p : w.points)
      for (int a = 0; a < 3; ++a)
        xyz[a].push_back(zigzag(quantize(static_cast<double>(p(a)), q.word_point_m, "word point coordinate")));
    for (const float d : w.descriptor)
      desc.push_back(static_cast<std::uint8_t>(static_cast<std::int8_t>(std::lround(d * kDescriptorScale))));
  }
  std::vector<std::uint8_t> raw;
  put_planes(raw, counts);
  for (const auto& c : xyz) put_planes(raw, c);
  raw.insert(raw.end(), desc.begin(), desc.end());
  put_chunk(out, "WORD", deflated_payload(xyz[0].size(), raw));
  put_chunk(out, "AEND", {});
  return out;
}

StatusOr<Alphabet> decode_alphabet(const std::vector<std::uint8_t>& bytes) {
  return decode_alphabet_at(bytes.data(), bytes.size(), Ctx{"alphabet file", 0});
}

std::uint64_t alphabet_hash(const std::vector<std::uint8_t>& alphabet_file) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (const std::uint8_t b : alphabet_file) {
    h ^= b;
    h *= 0x100000001b3ULL;
  }
  return h;
}

namespace {

// ---------------------------------------------------------------------------------------
// scan: the scan's stamp and frame (model.md §2.13)
// ---------------------------------------------------------------------------------------

std::vector<std::uint8_t> scan_payload(const ScanStamp& st) {
  if (st.nsec >= 1000000000U || (st.source != ScanStamp::Source::kMessage && st.source != ScanStamp::Source::kCapture) ||
      st.frame_id.size() > kMaxFrameIdBytes || st.frame_id.find('\0') != std::string::npos)
    throw std::invalid_argument("lex3d::codec::encode_model: invalid scan stamp (nanoseconds >= 1e9, unknown source, "
                                "or a frame_id with a NUL or over 1024 bytes)");
  std::vector<std::uint8_t> p;
  p.push_back(static_cast<std::uint8_t>(st.source));
  put_u64(p, st.sec);
  put_u32(p, st.nsec);
  put_u16(p, static_cast<std::uint16_t>(st.frame_id.size()));
  p.insert(p.end(), st.frame_id.begin(), st.frame_id.end());
  return p;
}

Status read_scan(const Chunk& c, const Ctx& ctx, ScanStamp& st) {
  const std::uint8_t* p = c.payload;
  const std::uint64_t base = c.payload_offset;
  if (c.length < kScanHeadBytes)
    return ctx.error("chunk 'scan' payload is " + std::to_string(c.length) + " bytes, at least " +
                         std::to_string(kScanHeadBytes) + " expected",
                     c.offset + 4);
  if (p[0] != static_cast<std::uint8_t>(ScanStamp::Source::kMessage) &&
      p[0] != static_cast<std::uint8_t>(ScanStamp::Source::kCapture))
    return ctx.error("scan stamp source " + std::to_string(p[0]) + " is neither 1 (a message) nor 2 (a capture)", base);
  st.source = static_cast<ScanStamp::Source>(p[0]);
  st.sec = ld_u64(p + 1);
  st.nsec = ld_u32(p + 9);
  if (st.nsec >= 1000000000U) return ctx.error("scan stamp nanoseconds " + std::to_string(st.nsec) + " are 1e9 or more", base + 9);
  const std::uint16_t n = ld_u16(p + 13);
  if (n > kMaxFrameIdBytes || c.length != kScanHeadBytes + n)
    return ctx.error("scan frame_id of " + std::to_string(n) + " bytes does not fill the chunk's " +
                         std::to_string(c.length - kScanHeadBytes) + " (at most " + std::to_string(kMaxFrameIdBytes) + ")",
                     base + 13);
  st.frame_id.assign(reinterpret_cast<const char*>(p + kScanHeadBytes), n);
  if (st.frame_id.find('\0') != std::string::npos) return ctx.error("scan frame_id holds a NUL byte", base + kScanHeadBytes);
  return {};
}

// ---------------------------------------------------------------------------------------
// GEOR: the georeference (model.md §2.9)
// ---------------------------------------------------------------------------------------

void put_fixed_string(std::vector<std::uint8_t>& b, const std::string& s, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) b.push_back(i < s.size() ? static_cast<std::uint8_t>(s[i]) : 0);
}

void put_string(std::vector<std::uint8_t>& b, const std::string& s, const char* what) {
  if (s.size() > kGeorMaxString)
    throw std::invalid_argument(std::string("lex3d::codec::encode_model: georeference ") + what + " longer than " +
                                std::to_string(kGeorMaxString) + " bytes");
  put_u16(b, static_cast<std::uint16_t>(s.size()));
  b.insert(b.end(), s.begin(), s.end());
}

/// The GEOR payload of `g`; its records deflated where that is smaller (`records_deflated`
/// says so).
std::vector<std::uint8_t> geor_payload(const Georeference& g, bool& records_deflated) {
  auto fail = [](const std::string& what) {
    throw std::invalid_argument("lex3d::codec::encode_model: georeference " + what);
  };
  if (!g.origin.allFinite() || g.origin.cwiseAbs().maxCoeff() > kGeorMaxOrigin) fail("origin not finite or beyond 1e9 m");
  for (double u : {g.unit_m, g.vertical_unit_m})
    if (!(u >= kGeorMinUnit && u <= kGeorMaxUnit)) fail("unit outside [1e-3, 1e4] m");
  const bool las = g.is_las();
  for (int a = 0; a < 3; ++a) {
    if (las && !(g.las_scale[a] > 0.0 && g.las_scale[a] <= 1e6)) fail("LAS scale outside (0, 1e6]");
    if (!las && g.las_scale[a] != 0.0) fail("LAS scale partly set");
    if (!std::isfinite(g.las_offset[a]) || std::abs(g.las_offset[a]) > 1e15) fail("LAS offset not finite");
  }
  if (g.las_version_minor > 4 || g.las_point_format > 10) fail("LAS version or point format out of range");
  std::vector<std::uint8_t> b;
  for (int a = 0; a < 3; ++a) put_f64(b, g.origin[a]);
  put_f64(b, g.unit_m);
  put_f64(b, g.vertical_unit_m);
  put_u32(b, g.epsg);
  for (int a = 0; a < 3; ++a) put_f64(b, g.las_scale[a]);
  for (int a = 0; a < 3; ++a) put_f64(b, g.las_offset[a]);
  b.push_back(g.las_version_minor);
  b.push_back(g.las_point_format);
  put_u16(b, g.las_global_encoding);
  put_string(b, g.crs_name, "CRS name");
  put_string(b, g.unit_name, "unit name");
  put_string(b, g.las_system_id, "system id");
  put_string(b, g.las_software, "software");
  if (g.crs_records.size() > kGeorMaxRecords) fail("has more than 256 CRS records");
  std::uint64_t total = 0;
  std::vector<std::uint8_t> records;
  for (const CrsRecord& r : g.crs_records) {
    total += r.data.size();
    if (total > kGeorMaxRecordBytes) fail("CRS records hold more than 1 MiB");
    if (r.user_id.size() > 16 || r.description.size() > 32) fail("CRS record user id or description too long");
    put_fixed_string(records, r.user_id, 16);
    put_u16(records, r.record_id);
    records.push_back(r.extended ? 1 : 0);
    put_fixed_string(records, r.description, 32);
    put_u32(records, static_cast<std::uint32_t>(r.data.size()));
    records.insert(records.end(), r.data.begin(), r.data.end());
  }
  // Deflated (format 1.12) where that saves bytes: a WKT string and GeoTIFF keys shrink to
  // about a third, 1,660 -> 720 bytes on hexbin's CRS (0.2 bits a point of its 38,367).
  const auto count = static_cast<std::uint32_t>(g.crs_records.size());
  records_deflated = false;
  if (!records.empty()) {
    const std::vector<std::uint8_t> z = deflated(records);
    if (4 + z.size() < records.size()) {
      records_deflated = true;
      put_u32(b, count | kGeorDeflatedBit);
      put_u32(b, static_cast<std::uint32_t>(records.size()));
      b.insert(b.end(), z.begin(), z.end());
      return b;
    }
  }
  put_u32(b, count);
  b.insert(b.end(), records.begin(), records.end());
  return b;
}

std::string fixed_string(const std::uint8_t* p, std::size_t n) {
  std::size_t len = 0;
  while (len < n && p[len] != 0) ++len;
  return std::string(reinterpret_cast<const char*>(p), len);
}

Status read_geor(const Chunk& c, const Ctx& ctx, std::uint16_t minor, Georeference& g) {
  const std::uint8_t* p = c.payload;
  const std::uint64_t base = c.payload_offset;
  if (c.length < kGeorFixedBytes + 4 * 2 + 4)
    return ctx.error("chunk 'GEOR' payload is " + std::to_string(c.length) + " bytes, at least " +
                         std::to_string(kGeorFixedBytes + 12) + " expected",
                     c.offset + 4);
  for (int a = 0; a < 3; ++a) {
    g.origin[a] = ld_f64(p + 8 * a);
    if (!std::isfinite(g.origin[a]) || std::abs(g.origin[a]) > kGeorMaxOrigin)
      return ctx.error("GEOR origin is not finite or lies beyond 1e9 m", base + 8 * static_cast<std::uint64_t>(a));
  }
  g.unit_m = ld_f64(p + 24);
  g.vertical_unit_m = ld_f64(p + 32);
  for (int k = 0; k < 2; ++k) {
    const double u = k == 0 ? g.unit_m : g.vertical_unit_m;
    if (!(u >= kGeorMinUnit && u <= kGeorMaxUnit))
      return ctx.error("GEOR unit of " + std::to_string(u) + " m is outside [0.001, 10000]", base + 24 + 8 * static_cast<std::uint64_t>(k));
  }
  g.epsg = ld_u32(p + 40);
  for (int a = 0; a < 3; ++a) {
    g.las_scale[a] = ld_f64(p + 44 + 8 * a);
    g.las_offset[a] = ld_f64(p + 68 + 8 * a);
  }
  const bool las = g.las_scale[0] > 0.0;
  for (int a = 0; a < 3; ++a) {
    const double s = g.las_scale[a];
    if (las ? !(s > 0.0 && s <= 1e6) : s != 0.0)
      return ctx.error("GEOR LAS scale " + std::to_string(s) + " is neither 0 (no LAS) for all axes nor in (0, 1e6]",
                       base + 44 + 8 * static_cast<std::uint64_t>(a));
    if (!std::isfinite(g.las_offset[a]) || std::abs(g.las_offset[a]) > 1e15)
      return ctx.error("GEOR LAS offset is not finite or beyond 1e15", base + 68 + 8 * static_cast<std::uint64_t>(a));
  }
  g.las_version_minor = p[92];
  g.las_point_format = p[93];
  if (g.las_version_minor > 4) return ctx.error("GEOR LAS minor version " + std::to_string(g.las_version_minor) + " is above 4", base + 92);
  if (g.las_point_format > 10) return ctx.error("GEOR LAS point format " + std::to_string(g.las_point_format) + " is above 10", base + 93);
  g.las_global_encoding = ld_u16(p + 94);
  std::uint64_t pos = kGeorFixedBytes;
  std::string* strings[] = {&g.crs_name, &g.unit_name, &g.las_system_id, &g.las_software};
  for (std::string* s : strings) {
    if (c.length - pos < 2) return ctx.error("GEOR ends inside its strings", base + pos);
    const std::uint16_t n = ld_u16(p + pos);
    if (n > kGeorMaxString || n > c.length - pos - 2)
      return ctx.error("GEOR string of " + std::to_string(n) + " bytes exceeds the " +
                           std::to_string(std::min<std::uint64_t>(kGeorMaxString, c.length - pos - 2)) + " allowed",
                       base + pos);
    s->assign(reinterpret_cast<const char*>(p + pos + 2), n);
    pos += 2 + n;
  }
  if (c.length - pos < 4) return ctx.error("GEOR ends before its record count", base + pos);
  const std::uint32_t count_field = ld_u32(p + pos);
  const std::uint32_t count = count_field & ~kGeorDeflatedBit;
  pos += 4;
  // Deflated records (format 1.12): raw_size u32, then the zlib stream to the payload's end;
  // the records are read from what it inflates to (offsets in messages are then the stream's).
  std::vector<std::uint8_t> inflated;
  std::uint64_t length = c.length;
  if ((count_field & kGeorDeflatedBit) != 0) {
    if (minor < kGeorDeflatedMinor)
      return ctx.error("GEOR records deflated (record count bit 31) need format version 1.12, the header says 1." +
                           std::to_string(minor),
                       base + pos - 4);
    if (c.length - pos < 4) return ctx.error("GEOR ends before its deflated records' size", base + pos);
    const std::uint32_t raw = ld_u32(p + pos);
    pos += 4;
    const std::uint64_t most = static_cast<std::uint64_t>(kGeorMaxRecords) * kGeorRecordHead + kGeorMaxRecordBytes;
    if (raw == 0 || raw > most || !inflatable(raw, c.length - pos))
      return ctx.error("GEOR deflated records' size " + std::to_string(raw) + " is 0, above " + std::to_string(most) +
                           " or more than the stored bytes can inflate to",
                       base + pos - 4);
    if (Status s = inflate_exact(p + pos, c.length - pos, raw, ctx, "'GEOR'", base + pos, inflated); !s.ok()) return s;
    p = inflated.data();
    pos = 0;
    length = inflated.size();
  }
  if (count > kGeorMaxRecords || count > (length - pos) / kGeorRecordHead)
    return ctx.error("GEOR record count " + std::to_string(count) + " is above 256 or more than the " +
                         std::to_string(length - pos) + " bytes left can hold",
                     base + pos - 4);
  std::uint64_t total = 0;
  g.crs_records.resize(count);
  for (std::uint32_t i = 0; i < count; ++i) {
    if (length - pos < kGeorRecordHead) return ctx.error("GEOR record " + std::to_string(i) + " header is truncated", base + pos);
    CrsRecord& r = g.crs_records[i];
    r.user_id = fixed_string(p + pos, 16);
    r.record_id = ld_u16(p + pos + 16);
    const std::uint8_t ext = p[pos + 18];
    if (ext > 1) return ctx.error("GEOR record " + std::to_string(i) + " extended flag is " + std::to_string(ext), base + pos + 18);
    r.extended = ext == 1;
    r.description = fixed_string(p + pos + 19, 32);
    const std::uint32_t len = ld_u32(p + pos + 51);
    pos += kGeorRecordHead;
    total += len;
    if (len > length - pos || total > kGeorMaxRecordBytes)
      return ctx.error("GEOR record " + std::to_string(i) + " length " + std::to_string(len) +
                           " exceeds the bytes left or the 1 MiB of all records",
                       base + pos - 4);
    r.data.assign(p + pos, p + pos + len);
    pos += len;
  }
  if (pos != length)
    return ctx.error(std::to_string(length - pos) + " bytes after the last GEOR record", base + pos);
  return {};
}

}  // namespace

std::vector<std::uint8_t> encode_model(const ModelData& data, const Quantization& q) {
  q.validate();
  const bool embed = data.alphabet.has_value();
  if (!embed && !data.alphabet_hash)
    throw std::invalid_argument("lex3d::codec::encode_model: set ModelData::alphabet (embedded) or alphabet_hash");
  if (!data.T_cloud_sensor.translation().allFinite() || !orthonormal(data.T_cloud_sensor.linear()))
    throw std::invalid_argument("lex3d::codec::encode_model: T_cloud_sensor is not a finite rigid transform");
  if (embed)
    for (std::size_t i = 0; i < data.model.instances.size(); ++i)
      if (data.model.instances[i].word >= data.alphabet->size())
        throw std::invalid_argument("lex3d::codec::encode_model: instance " + std::to_string(i) + " has word id " +
                                    std::to_string(data.model.instances[i].word) + ", the alphabet has " +
                                    std::to_string(data.alphabet->size()) + " words");

  if (data.attributes && data.attributes->empty())
    throw std::invalid_argument("lex3d::codec::encode_model: an empty attribute chunk (use nullopt for none)");
  if (data.residual && data.residual->empty())
    throw std::invalid_argument("lex3d::codec::encode_model: an empty residual layer (use nullopt for none)");

  // A layer's chunk and the file's minor version follow its coding: a RESD layer makes a
  // file of format 1.1 that older readers still take.
  const std::uint32_t coding = data.residual ? layer_coding(*data.residual) : 0U;
  if (coding >= kLayerCodings)
    throw std::invalid_argument("lex3d::codec::encode_model: residual layer of unknown coding " + std::to_string(coding));
  const LayerChunk& layer_chunk = kLayerChunks[coding];
  std::vector<std::uint8_t> out;
  std::uint16_t minor = data.residual ? layer_chunk.minor : kMinor;
  if (data.georef) minor = std::max(minor, kGeorMinor);
  if (data.attributes) minor = std::max(minor, kAttrMinor);
  if (data.residual) minor = std::max(minor, laser_predictor_minor(*data.residual));
  if (data.residual && laser_short_layer(*data.residual)) minor = std::max(minor, kLaserShortMinor);
  if (data.residual && voxel_mixed_layer(*data.residual)) minor = std::max(minor, kVoxelMixedMinor);
  if (data.residual && layer_1_13_field(*data.residual) != 0) minor = std::max(minor, kLayerFieldsMinor);
  if (data.attributes) minor = std::max(minor, attributes_minor(data.attributes->data(), data.attributes->size()));
  // A model without instances has no INST chunk and the short MHDR; one without words at
  // all (an empty embedded alphabet) no alphabet either: 292 bytes fewer (format 1.11).
  const bool instances = !data.model.instances.empty();
  const bool wordless = embed && !instances && data.alphabet->size() == 0;
  if (!instances) minor = std::max(minor, kNoInstancesMinor);
  bool geor_deflated = false;
  const std::vector<std::uint8_t> geor = data.georef ? geor_payload(*data.georef, geor_deflated) : std::vector<std::uint8_t>{};
  if (geor_deflated) minor = std::max(minor, kGeorDeflatedMinor);
  put_header(out, kModelMagic, wordless ? 0U : embed ? kFlagAlphabetEmbedded : kFlagAlphabetReferenced, minor);

  std::vector<std::uint8_t> mhdr;
  put_u64(mhdr, data.input_points);
  if (instances || !data.T_cloud_sensor.matrix().isIdentity(0.0)) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) put_f64(mhdr, data.T_cloud_sensor.linear()(r, c));
    for (int a = 0; a < 3; ++a) put_f64(mhdr, data.T_cloud_sensor.translation()(a));
  }
  if (instances) {
    put_f64(mhdr, q.translation_m);
    put_f64(mhdr, q.rotation_rad);
  }
  put_chunk(out, "MHDR", mhdr);

  if (embed && !wordless) {
    put_chunk(out, "ALPH", encode_alphabet(*data.alphabet, q));
  } else if (!embed) {
    std::vector<std::uint8_t> aref;
    put_u64(aref, *data.alphabet_hash);
    put_chunk(out, "AREF", aref);
  }
  if (instances) put_chunk(out, "INST", inst_payload(data.model, q));
  if (data.residual) put_chunk(out, layer_chunk.type, *data.residual);
  if (data.georef) put_chunk(out, kGeorType, geor);
  if (data.attributes) put_chunk(out, kAttrType, *data.attributes);
  if (data.stamp) put_chunk(out, kScanType, scan_payload(*data.stamp));
  put_chunk(out, "IEND", {});
  return out;
}

StatusOr<ModelData> decode_model(const std::vector<std::uint8_t>& bytes,
                                 const std::vector<std::uint8_t>* external_alphabet_file) {
  const Ctx ctx{"model file", 0};
  const std::uint8_t* d = bytes.data();
  Header h;
  if (Status s = read_header(d, bytes.size(), ctx, kModelMagic, kAlphabetMagic, "alphabet", true, h); !s.ok())
    return s;
  if ((h.flags & ~(kFlagAlphabetEmbedded | kFlagAlphabetReferenced)) != 0)
    return ctx.error("reserved flag bits " + hex(h.flags & ~(kFlagAlphabetEmbedded | kFlagAlphabetReferenced), 8) +
                         " set",
                     12);
  const bool embedded = (h.flags & kFlagAlphabetEmbedded) != 0;
  const bool referenced = (h.flags & kFlagAlphabetReferenced) != 0;
  if (embedded && referenced)
    return ctx.error("flags " + hex(h.flags, 8) +
                         " set both bit 0 (alphabet embedded) and bit 1 (alphabet referenced)",
                     12);
  // Neither: a model without words, which has no alphabet (format 1.11).
  const bool wordless = !embedded && !referenced;
  if (wordless && h.minor < kNoInstancesMinor)
    return ctx.error("flags " + hex(h.flags, 8) +
                         " must set one of bit 0 (alphabet embedded) and bit 1 (alphabet referenced) before format "
                         "version 1." + std::to_string(kNoInstancesMinor) + ", the header says 1." +
                         std::to_string(h.minor),
                     12);

  ModelData out;
  MhdrFields mhdr;
  // A file without a residual layer has none of the layer chunks, one with a layer exactly
  // one, in a file of at least the minor version that introduced it.
  const LayerChunk* layer_chunk = nullptr;
  for (const LayerChunk& lc : kLayerChunks) {
    if (!has_chunk(d, bytes.size(), lc.type)) continue;
    if (layer_chunk != nullptr)
      return ctx.error(std::string("a model file holds at most one of the chunks 'RESD', 'RESW', 'RESV', 'RESL', 'RESA' and 'RESG' ('") +
                           layer_chunk->type + "' and '" + lc.type + "' found)",
                       20);
    layer_chunk = &lc;
  }
  const bool has_residual = layer_chunk != nullptr;
  if (has_residual && h.minor < layer_chunk->minor)
    return ctx.error(std::string("chunk '") + layer_chunk->type + "' needs format version 1." +
                         std::to_string(layer_chunk->minor) + ", the header says 1." + std::to_string(h.minor),
                     10);
  const bool has_geor = has_chunk(d, bytes.size(), kGeorType);
  if (has_geor && h.minor < kGeorMinor)
    return ctx.error("chunk 'GEOR' needs format version 1." + std::to_string(kGeorMinor) + ", the header says 1." +
                         std::to_string(h.minor),
                     10);
  const bool has_attr = has_chunk(d, bytes.size(), kAttrType);
  if (has_attr && h.minor < kAttrMinor)
    return ctx.error("chunk 'ATTR' needs format version 1." + std::to_string(kAttrMinor) + ", the header says 1." +
                         std::to_string(h.minor),
                     10);
  // INST: required before format 1.11, then only where there are instances; never
  // without an alphabet.
  const bool has_inst = !wordless && (h.minor < kNoInstancesMinor || has_chunk(d, bytes.size(), "INST"));
  const std::vector<const char*> known = {"MHDR", "ALPH", "AREF", "INST", "RESD", "RESW", "RESV", "RESL", "RESA", "RESG", kGeorType, kAttrType, "IEND"};
  std::vector<const char*> sequence = {"MHDR"};
  if (!wordless) sequence.push_back(embedded ? "ALPH" : "AREF");
  if (has_inst) sequence.push_back("INST");
  if (has_residual) sequence.push_back(layer_chunk->type);
  if (has_geor) sequence.push_back(kGeorType);
  if (has_attr) sequence.push_back(kAttrType);
  sequence.push_back("IEND");
  if (wordless) out.alphabet = Alphabet{};
  // (the optional `scan` chunk: anywhere between MHDR and IEND, at most once)
  const auto on_optional = [&](const Chunk& c) -> Status {
    if (!c.is(kScanType)) return {};
    if (out.stamp) return ctx.error("chunk 'scan' is repeated", c.offset);
    return read_scan(c, ctx, out.stamp.emplace());
  };
  const Status s = walk_chunks(d, bytes.size(), ctx, sequence, known, [&](std::size_t, const Chunk& c) -> Status {
    if (c.is(kGeorType)) return read_geor(c, ctx, h.minor, out.georef.emplace());
    if (c.is(kAttrType)) {
      if (c.length == 0) return ctx.error("chunk 'ATTR' is empty", c.offset + 4);
      if (const std::uint16_t needed = attributes_minor(c.payload, c.length); h.minor < needed)
        return ctx.error(std::string("chunk 'ATTR' holds ") +
                             (needed == kAttrSourceMinor  ? "a ring, intensity or time with its source's name and type"
                              : needed == kAttrTypedMinor ? "a named field with its type"
                                                          : "a named field or colour differences") +
                             ", which need format version 1." + std::to_string(needed) + ", the header says 1." +
                             std::to_string(h.minor),
                         c.payload_offset);
      out.attributes.emplace(c.payload, c.payload + c.length);
      return {};
    }
    if (c.is("MHDR")) return read_mhdr(c, ctx, has_inst, mhdr);
    if (c.is("ALPH")) {
      auto a = decode_alphabet_at(c.payload, static_cast<std::size_t>(c.length),
                                  Ctx{"model file: embedded alphabet (ALPH)", c.payload_offset});
      if (!a.ok()) return a.status();
      out.alphabet = std::move(a).value();
      return {};
    }
    if (c.is("AREF")) {
      if (Status e = expect_length(c, kArefBytes, ctx); !e.ok()) return e;
      const std::uint64_t want = ld_u64(c.payload);
      out.alphabet_hash = want;
      if (external_alphabet_file == nullptr)
        return {ErrorCode::kInvalidArgument,
                "model file references an external alphabet file (hash " + hex(want, 16) + "); supply it",
                c.payload_offset};
      const std::uint64_t got = alphabet_hash(*external_alphabet_file);
      if (got != want)
        return ctx.error("the alphabet file's hash " + hex(got, 16) + " does not match the model's alphabet_hash " +
                             hex(want, 16),
                         c.payload_offset);
      auto a = decode_alphabet_at(external_alphabet_file->data(), external_alphabet_file->size(),
                                  Ctx{"external alphabet file", 0});
      if (!a.ok()) return a.status();
      out.alphabet = std::move(a).value();
      return {};
    }
    if (c.is("INST")) return read_inst(c, ctx, mhdr, out.alphabet->size(), out.model);
    if (c.is("IEND")) return {};
    // the layer chunk (the other known chunks are taken above)
    if (c.length == 0) return ctx.error(std::string("chunk '") + layer_chunk->type + "' is empty", c.offset + 4);
    out.residual.emplace(c.payload, c.payload + c.length);
    const std::uint32_t coding = layer_coding(*out.residual);
    if (coding >= kLayerCodings)
      return ctx.error(std::string("chunk '") + layer_chunk->type + "' holds a layer of unknown coding " +
                           std::to_string(coding),
                       c.payload_offset);
    if (&kLayerChunks[coding] != layer_chunk)
      return ctx.error(std::string("chunk '") + layer_chunk->type + "' (the " + layer_chunk->coding +
                           " coding) holds a layer of the " +
                           kLayerChunks[coding].coding + " coding, which belongs in an '" +
                           kLayerChunks[coding].type + "' chunk (formats/model.md §2.5-2.8, §2.11, §2.12)",
                       c.payload_offset);
    if (const std::uint16_t need = laser_predictor_minor(*out.residual); h.minor < need) {
      const std::uint32_t field = ld_u32(out.residual->data() + kLaserPredictorOffset);
      return ctx.error(std::string("a sensor-geometry layer ") +
                           ((field & kLaserQuickModelsBit) != 0
                                ? "whose mixed models learn at the quick rates (predictor field bit 10)"
                                : (field & kLaserMotionBit) != 0
                                ? "whose beams move over the turn (predictor field bit 9)"
                                : (field & kLaserTablePredictorsBit) != 0
                                ? "whose laser table picks its predictors (predictor field bit 8)"
                                : "with range predictor " + std::to_string(field)) +
                           " needs format version 1." + std::to_string(need) + ", the header says 1." +
                           std::to_string(h.minor),
                       c.payload_offset + kLaserPredictorOffset);
    }
    if (laser_short_layer(*out.residual) && h.minor < kLaserShortMinor)
      return ctx.error("a sensor-geometry layer without T_sensor_head (marker 0xFFFFFFFE) needs format version 1." +
                           std::to_string(kLaserShortMinor) + ", the header says 1." + std::to_string(h.minor),
                       c.payload_offset + 4);
    if (voxel_mixed_layer(*out.residual) && h.minor < kVoxelMixedMinor)
      return ctx.error("a voxel layer with octree contexts " +
                           std::to_string(out.residual->data()[kVoxelContextsOffset]) +
                           " needs format version 1." + std::to_string(kVoxelMixedMinor) + ", the header says 1." +
                           std::to_string(h.minor),
                       c.payload_offset + kVoxelContextsOffset);
    if (const std::size_t at = layer_1_13_field(*out.residual); at != 0 && h.minor < kLayerFieldsMinor) {
      const std::string field = std::to_string(ld_u32(out.residual->data() + at));
      return ctx.error((at == kAcquisitionFitOffset
                            ? "an acquisition-order layer with prediction field " + field + " (a line fit or tall cells)"
                            : "a lattice layer with stacked cells (order field " + field + ")") +
                           " needs format version 1." + std::to_string(kLayerFieldsMinor) + ", the header says 1." +
                           std::to_string(h.minor),
                       c.payload_offset + at);
    }
    return {};
  }, on_optional);
  if (!s.ok()) return s;
  out.input_points = mhdr.input_points;
  out.T_cloud_sensor = mhdr.T_cloud_sensor;
  return out;
}

// ---------------------------------------------------------------------------------------
// Sequence file (sequence.md)
// ---------------------------------------------------------------------------------------

bool is_sequence_file(const std::vector<std::uint8_t>& bytes) {
  return bytes.size() >= 8 && std::memcmp(bytes.data(), kSequenceMagic, 8) == 0;
}

std::vector<std::uint8_t> encode_sequence(const SequenceData& data) {
  auto alphabet = decode_alphabet(data.alphabet_file);
  if (!alphabet.ok())
    throw std::invalid_argument("lex3d::codec::encode_sequence: the alphabet file is invalid: " + alphabet.status().to_string());
  for (std::size_t i = 0; i < data.model_files.size(); ++i) {
    const auto m = decode_model(data.model_files[i], &data.alphabet_file);
    if (!m.ok() || !m.value().alphabet_hash)
      throw std::invalid_argument("lex3d::codec::encode_sequence: model " + std::to_string(i) +
                                  " is not a model file referencing the sequence's alphabet" +
                                  (m.ok() ? std::string() : ": " + m.status().to_string()));
  }
  if (!data.names.empty()) {
    if (data.names.size() != data.model_files.size())
      throw std::invalid_argument("lex3d::codec::encode_sequence: " + std::to_string(data.names.size()) +
                                  " names for " + std::to_string(data.model_files.size()) + " scans");
    std::set<std::string> seen;
    for (const auto& n : data.names)
      if (!is_valid_scan_name(n) || !seen.insert(n).second)
        throw std::invalid_argument("lex3d::codec::encode_sequence: scan name '" + n + "' is invalid or repeated");
  }
  std::vector<std::uint8_t> out;
  // 1.0 when the scans have no names: such files keep the bytes of the first version.
  put_header(out, kSequenceMagic, 0, data.names.empty() ? 0 : 1);
  std::vector<std::uint8_t> qhdr;
  put_u64(qhdr, data.model_files.size());
  put_chunk(out, "QHDR", qhdr);
  put_chunk(out, "ALPH", data.alphabet_file);
  if (!data.names.empty()) {
    std::vector<std::uint8_t> snam;
    for (const auto& n : data.names) {
      put_u16(snam, static_cast<std::uint16_t>(n.size()));
      snam.insert(snam.end(), n.begin(), n.end());
    }
    put_chunk(out, "snam", snam);
  }
  for (const auto& m : data.model_files) put_chunk(out, "SCAN", m);
  put_chunk(out, "QEND", {});
  return out;
}

bool is_valid_scan_name(const std::string& name) {
  if (name.empty() || name.size() > kMaxScanNameBytes || name == "." || name == "..") return false;
  return name.find_first_of(std::string("/\\\0", 3)) == std::string::npos;
}

StatusOr<SequenceData> decode_sequence(const std::vector<std::uint8_t>& bytes) {
  const Ctx ctx{"sequence file", 0};
  const std::uint8_t* d = bytes.data();
  const std::size_t size = bytes.size();
  Header h;
  if (Status s = read_header(d, size, ctx, kSequenceMagic, kModelMagic, "model", true, h); !s.ok()) return s;
  if (h.flags != 0) return ctx.error("reserved flag bits " + hex(h.flags, 8) + " set", 12);
  SequenceData out;
  std::uint64_t count = 0;
  // 0: expect QHDR, 1: ALPH, 2: SCAN or QEND.
  int state = 0;
  for (std::size_t pos = kHeaderBytes;;) {
    if (pos == size) return ctx.error("file ends before the 'QEND' chunk", pos);
    Chunk c;
    if (Status s = read_chunk(d, size, pos, ctx, c); !s.ok()) return s;
    const std::size_t next = static_cast<std::size_t>(c.payload_offset + c.length + kChunkCrcBytes);
    const bool known = c.is("QHDR") || c.is("ALPH") || c.is("SCAN") || c.is("QEND");
    if (c.is("snam") && state > 0) {  // the scans' names (1.1): one a scan, checked, once
      if (!out.names.empty() || count == 0)
        return ctx.error(count == 0 ? "chunk 'snam' in a file without scans" : "chunk 'snam' is repeated", pos);
      std::set<std::string> seen;
      std::uint64_t at = 0;
      for (std::uint64_t i = 0; i < count; ++i) {
        if (c.length - at < 2) return ctx.error("chunk 'snam' ends inside name " + std::to_string(i), c.payload_offset + at);
        const std::uint16_t n = ld_u16(c.payload + at);
        if (c.length - at - 2 < n)
          return ctx.error("chunk 'snam': name " + std::to_string(i) + " of " + std::to_string(n) +
                               " bytes does not fit the chunk", c.payload_offset + at);
        std::string name(reinterpret_cast<const char*>(c.payload + at + 2), n);
        if (!is_valid_scan_name(name) || !seen.insert(name).second)
          return ctx.error("chunk 'snam': name " + std::to_string(i) + " is empty, too long, repeated or holds '/', '\\' or NUL",
                           c.payload_offset + at);
        out.names.push_back(std::move(name));
        at += 2U + n;
      }
      if (at != c.length)
        return ctx.error("chunk 'snam' has " + std::to_string(c.length - at) + " bytes after its names", c.payload_offset + at);
      pos = next;
      continue;
    }
    if (!known) {
      if (state == 0) return ctx.error("the first chunk must be 'QHDR', found " + c.name, pos);
      if (c.required()) return ctx.error("unknown required chunk " + c.name, pos);
      pos = next;
      continue;
    }
    if (state == 0) {
      if (!c.is("QHDR")) return ctx.error("the first chunk must be 'QHDR', found " + c.name, pos);
      if (Status e = expect_length(c, kQhdrBytes, ctx); !e.ok()) return e;
      count = ld_u64(c.payload);
      // Every SCAN chunk takes at least 16 bytes of framing.
      if (count > (size - next) / (kChunkHeadBytes + kChunkCrcBytes))
        return ctx.error("QHDR scan_count " + std::to_string(count) + " cannot fit in the " +
                             std::to_string(size - next) + " bytes left",
                         c.payload_offset);
      out.model_files.reserve(static_cast<std::size_t>(count));
      state = 1;
    } else if (state == 1) {
      if (!c.is("ALPH")) return ctx.error("chunk " + c.name + " comes before the required chunk 'ALPH'", pos);
      out.alphabet_file.assign(c.payload, c.payload + c.length);
      auto a = decode_alphabet_at(c.payload, static_cast<std::size_t>(c.length),
                                  Ctx{"sequence file: alphabet (ALPH)", c.payload_offset});
      if (!a.ok()) return a.status();
      state = 2;
    } else if (c.is("SCAN")) {
      if (out.model_files.size() >= count)
        return ctx.error("more 'SCAN' chunks than QHDR scan_count " + std::to_string(count), pos);
      out.model_files.emplace_back(c.payload, c.payload + c.length);
    } else if (c.is("QEND")) {
      if (out.model_files.size() != count)
        return ctx.error(std::to_string(out.model_files.size()) + " 'SCAN' chunks, QHDR scan_count says " +
                             std::to_string(count),
                         pos);
      if (c.length != 0)
        return ctx.error("end chunk 'QEND' must be empty, has " + std::to_string(c.length) + " bytes", c.offset + 4);
      if (next != size) return ctx.error(std::to_string(size - next) + " bytes after the end chunk 'QEND'", next);
      return out;
    } else {
      return ctx.error("chunk " + c.name + " is repeated or out of order", pos);
    }
    pos = next;
  }
}

StatusOr<FileInfo> inspect(const std::vector<std::uint8_t>& bytes) {
  const std::uint8_t* d = bytes.data();
  const std::size_t size = bytes.size();
  FileInfo info;
  info.file_bytes = size;
  Header h;
  const bool alphabet = size >= 8 && std::memcmp(d, kAlphabetMagic, 8) == 0;
  const bool sequence = is_sequence_file(bytes);
  info.kind = alphabet ? "alphabet" : sequence ? "sequence" : "model";
  const Ctx ctx{info.kind + " file", 0};
  const Status hs = alphabet   ? read_header(d, size, ctx, kAlphabetMagic, kModelMagic, "model", false, h)
                    : sequence ? read_header(d, size, ctx, kSequenceMagic, kModelMagic, "model", false, h)
                               : read_header(d, size, ctx, kModelMagic, kAlphabetMagic, "alphabet", false, h);
  if (!hs.ok()) return hs;
  info.major = h.major;
  info.minor = h.minor;
  info.flags = h.flags;
  info.header_crc_ok = h.crc_ok;
  for (std::size_t pos = kHeaderBytes; pos < size;) {
    Chunk c;
    if (Status s = frame_chunk(d, size, pos, ctx, c); !s.ok()) return s;
    std::string type(4, '?');  // four characters; anything not printable shows as '?'
    for (std::size_t k = 0; k < 4; ++k)
      if (c.type[k] >= 0x20 && c.type[k] < 0x7F) type[k] = static_cast<char>(c.type[k]);
    const bool crc_ok = c.stored_crc == c.computed_crc;
    info.chunks.push_back({type, c.offset, c.length, crc_ok});
    // The header chunks' figures (model.md §2.1, alphabet.md AHDR), from intact chunks.
    if (crc_ok && type == "MHDR" && c.length == 120) {
      info.translation_step_m = ld_f64(c.payload + 104);
      info.rotation_step_rad = ld_f64(c.payload + 112);
    } else if (crc_ok && type == "AHDR" && c.length >= 32) {
      info.word_radius_m = ld_f64(c.payload);
      info.point_spacing_m = ld_f64(c.payload + 8);
      info.word_point_step_m = ld_f64(c.payload + 24);
    }
    pos = static_cast<std::size_t>(c.payload_offset + c.length + kChunkCrcBytes);
  }
  return info;
}

}  // namespace lex3d::codec
