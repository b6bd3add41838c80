// sensor_msgs/PointCloud2 read from its ROS 1 serialization, and the record structure of a
// bag 2.0 file checked before the ROS bag library reads it. No ROS header is needed here:
// both follow the published formats (wiki.ros.org/msg serialization, Bags/Format/2.0), and
// every length is checked against the bytes left before anything is allocated.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <bzlib.h>
#include <lz4frame.h>

#include "io/internal.hpp"
#include "io/rosbag_internal.hpp"

namespace lex3d::io::detail {

namespace {

/// Little-endian cursor over a message's bytes.
class Reader {
 public:
  Reader(const std::uint8_t* p, std::size_t n) : p_(p), n_(n) {}
  bool u8(std::uint8_t& v) { return take(&v, 1); }
  bool u32(std::uint32_t& v) { return take(&v, 4); }
  bool u64(std::uint64_t& v) { return take(&v, 8); }
  bool string(std::string& s, std::size_t cap) {
    std::uint32_t len = 0;
    if (!u32(len) || len > left() || len > cap) return false;
    s.assign(reinterpret_cast<const char*>(p_ + at_), len);
    at_ += len;
    return true;
  }
  bool bytes(const std::uint8_t*& b, std::size_t& len) {
    std::uint32_t l = 0;
    if (!u32(l) || l > left()) return false;
    b = p_ + at_;
    len = l;
    at_ += l;
    return true;
  }
  [[nodiscard]] std::size_t left() const { return n_ - at_; }
  [[nodiscard]] std::size_t at() const { return at_; }

 private:
  bool take(void* v, std::size_t k) {
    if (k > left()) return false;
    std::memcpy(v, p_ + at_, k);  // the decoders assume a little-endian host (sensor_log.cpp)
    at_ += k;
    return true;
  }
  const std::uint8_t* p_;
  std::size_t n_;
  std::size_t at_ = 0;
};

constexpr std::size_t kMaxNameBytes = 4096;
constexpr std::uint32_t kMaxPointFields = 1U << 12;

bool scalar_of(std::uint8_t datatype, Scalar& s) {
  switch (datatype) {
    case 1: s = Scalar::kI8; return true;
    case 2: s = Scalar::kU8; return true;
    case 3: s = Scalar::kI16; return true;
    case 4: s = Scalar::kU16; return true;
    case 5: s = Scalar::kI32; return true;
    case 6: s = Scalar::kU32; return true;
    case 7: s = Scalar::kF32; return true;
    case 8: s = Scalar::kF64; return true;
    default: return false;
  }
}

bool is_integer(Scalar s) { return s != Scalar::kF32 && s != Scalar::kF64; }

}  // namespace

Status parse_pointcloud2(const std::string& where, const std::uint8_t* p, std::size_t n, PointCloud2Msg& m) {
  Reader r(p, n);
  auto cut = [&](const char* what) {
    return bad_data(where + ": truncated PointCloud2 message (" + std::to_string(n) + " bytes) in its " + what, r.at());
  };
  if (!r.u32(m.seq) || !r.u32(m.stamp_sec) || !r.u32(m.stamp_nsec)) return cut("header");
  if (!r.string(m.frame_id, kMaxNameBytes)) return cut("header's frame_id");
  if (!r.u32(m.height) || !r.u32(m.width)) return cut("height and width");
  std::uint32_t nf = 0;
  if (!r.u32(nf)) return cut("fields");
  // a field takes at least 13 bytes: checked against the bytes left before the vector grows
  if (nf > kMaxPointFields || static_cast<std::uint64_t>(nf) * 13U > r.left())
    return bad_data(where + ": PointCloud2 declares " + std::to_string(nf) + " fields, more than its " +
                        std::to_string(r.left()) + " bytes left can hold",
                    r.at());
  m.fields.resize(nf);
  for (auto& f : m.fields) {
    if (!r.string(f.name, kMaxNameBytes) || !r.u32(f.offset) || !r.u8(f.datatype) || !r.u32(f.count))
      return cut("fields");
  }
  std::uint8_t big = 0, dense = 0;
  if (!r.u8(big) || !r.u32(m.point_step) || !r.u32(m.row_step)) return cut("point_step and row_step");
  m.is_bigendian = big != 0;
  if (!r.bytes(m.data, m.data_size)) return cut("data");
  if (!r.u8(dense)) return cut("is_dense");
  m.is_dense = dense != 0;
  if (r.left() != 0)
    return bad_data(where + ": PointCloud2 message has " + std::to_string(r.left()) + " bytes after its end", r.at());
  return {};
}

bool parse_byte_array(const std::uint8_t* p, std::size_t n, const std::uint8_t*& bytes, std::size_t& size) {
  Reader r(p, n);
  return r.bytes(bytes, size);
}

Status pointcloud2_to_cloud(const std::string& where, const PointCloud2Msg& m, ReadResult& r) {
  if (m.is_bigendian)
    return bad_data(where + ": is_bigendian is set: big-endian PointCloud2 data is not read (lex3d reads the "
                            "little-endian data every ROS driver writes)");
  struct Field {
    const PointField2* f = nullptr;
    Scalar scalar = Scalar::kF32;
  };
  std::vector<Field> fields;
  std::set<std::string> names;
  for (const PointField2& f : m.fields) {
    Field x;
    x.f = &f;
    const std::string name = "field " + quoted(f.name);
    if (!scalar_of(f.datatype, x.scalar))
      return bad_data(where + ": " + name + " has unknown datatype " + std::to_string(f.datatype) +
                      " (sensor_msgs/PointField: 1 INT8 ... 8 FLOAT64)");
    if (!names.insert(to_lower(f.name)).second) return bad_data(where + ": " + name + " appears twice");
    const std::uint64_t end = static_cast<std::uint64_t>(f.offset) + std::uint64_t{scalar_size(x.scalar)} * f.count;
    if (f.count == 0) return bad_data(where + ": " + name + " has count 0");
    if (end > m.point_step)
      return bad_data(where + ": " + name + " (offset " + std::to_string(f.offset) + ", " +
                      std::to_string(end - f.offset) + " bytes) does not fit point_step " + std::to_string(m.point_step));
    fields.push_back(x);
  }
  auto find = [&](std::initializer_list<const char*> wanted) -> const Field* {
    for (const char* w : wanted)
      for (const Field& f : fields)
        if (to_lower(f.f->name) == w) return &f;
    return nullptr;
  };
  const Field* fx = find({"x"});
  const Field* fy = find({"y"});
  const Field* fz = find({"z"});
  if (fx == nullptr || fy == nullptr || fz == nullptr)
    return bad_data(where + ": PointCloud2 has no '" + std::string(fx == nullptr ? "x" : fy == nullptr ? "y" : "z") +
                    "' field");
  for (const Field* f : {fx, fy, fz})
    if (f->f->count != 1)
      return bad_data(where + ": field " + quoted(f->f->name) + " has count " + std::to_string(f->f->count) + ", expected 1");
  const Field* fi = find({"intensity"});
  const Field* fr = find({"ring", "laser_id", "ring_id"});
  const Field* ft = find({"time", "t", "timestamp"});
  const Field* fc = find({"rgb", "rgba"});
  if (fc != nullptr && scalar_size(fc->scalar) != 4) fc = nullptr;  // only packed 32-bit colours
  // Every other field: a single integer of up to 32 bits (an unsigned 32-bit one while its
  // values fit in 31 bits) with a plain name is kept as a named field (Cloud::fields, e.g.
  // an Ouster driver's reflectivity, ambient and range); the rest are named as not kept.
  std::vector<const Field*> extras;
  std::vector<FieldSpec> extra_names;
  for (const Field& f : fields) {
    const bool used = &f == fx || &f == fy || &f == fz || &f == fi || &f == fr || &f == ft || &f == fc;
    if (used) {
      if (f.f->count != 1) r.dropped_fields.push_back(f.f->name + " elements 2-" + std::to_string(f.f->count));
      continue;
    }
    if (offer_field(f.f->name, f.scalar, f.f->count, extra_names, r.dropped_fields)) extras.push_back(&f);
  }
  // sizes: row_step holds a row's points, the data holds height rows
  const std::uint64_t row_bytes = static_cast<std::uint64_t>(m.width) * m.point_step;
  if (m.row_step < row_bytes)
    return bad_data(where + ": row_step " + std::to_string(m.row_step) + " is smaller than width " +
                    std::to_string(m.width) + " x point_step " + std::to_string(m.point_step));
  const std::uint64_t need = static_cast<std::uint64_t>(m.height) * m.row_step;
  if (need != m.data_size)
    return bad_data(where + ": data holds " + std::to_string(m.data_size) + " bytes, height " + std::to_string(m.height) +
                    " x row_step " + std::to_string(m.row_step) + " = " + std::to_string(need));
  if (m.point_step == 0 && static_cast<std::uint64_t>(m.width) * m.height > 0)
    return bad_data(where + ": point_step is 0");
  if (ft != nullptr && is_integer(ft->scalar))
    r.notes.push_back("the integer time field " + quoted(ft->f->name) + " is read as nanoseconds (the ouster_ros convention)");
  const double time_scale = ft != nullptr && is_integer(ft->scalar) ? 1e-9 : 1.0;

  const bool wide = fx->scalar == Scalar::kF64 || fy->scalar == Scalar::kF64 || fz->scalar == Scalar::kF64;
  Builder out(r, fi != nullptr, fc != nullptr, wide);
  out.set_time(ft != nullptr);
  out.set_fields(extra_names);
  // (how the ring, intensity and time were stored, for the writers to give them back so)
  if (fr != nullptr) r.cloud.ring_source = source_field(fr->f->name, fr->scalar);
  if (fi != nullptr) r.cloud.intensity_source = source_field(fi->f->name, fi->scalar);
  if (ft != nullptr) r.cloud.time_source = source_field(ft->f->name, ft->scalar);
  const bool organised = m.height > 1 && m.height <= 0xFFFF;
  if (organised) {
    r.cloud.rows = m.height;
    r.cloud.columns = m.width;
  }
  out.set_layout(organised || fr != nullptr, organised, organised);
  const auto n = static_cast<std::size_t>(std::uint64_t{m.width} * m.height);
  out.reserve(n);
  if (ft != nullptr) r.cloud.time.reserve(n);
  if (organised || fr != nullptr) r.cloud.ring.reserve(n);
  if (organised) r.cloud.column.reserve(n);
  const bool swap = false;
  for (std::uint32_t row = 0; row < m.height; ++row) {
    const std::uint8_t* base = m.data + static_cast<std::size_t>(row) * m.row_step;
    for (std::uint32_t col = 0; col < m.width; ++col) {
      const std::uint8_t* pt = base + static_cast<std::size_t>(col) * m.point_step;
      const float in = fi != nullptr ? load_float(pt + fi->f->offset, fi->scalar, swap) : 0.0F;
      Rgb c{};
      if (fc != nullptr) {
        const auto v = load<std::uint32_t>(pt + fc->f->offset, swap);
        c = {static_cast<std::uint8_t>((v >> 16) & 0xFFU), static_cast<std::uint8_t>((v >> 8) & 0xFFU),
             static_cast<std::uint8_t>(v & 0xFFU)};
      }
      std::uint16_t ring = static_cast<std::uint16_t>(row);
      if (fr != nullptr) {
        const double v = load_scalar(pt + fr->f->offset, fr->scalar, swap);
        if (!(v >= 0.0 && v <= 65535.0) || v != std::floor(v))
          return bad_data(where + ": point " + std::to_string(std::uint64_t{row} * m.width + col) + ": " + fr->f->name +
                          " value is not a laser index in [0, 65535]");
        ring = static_cast<std::uint16_t>(v);
      }
      if (ft != nullptr) out.next_time(load_scalar(pt + ft->f->offset, ft->scalar, swap) * time_scale);
      for (std::size_t e = 0; e < extras.size(); ++e)
        out.next_field(e, load_scalar(pt + extras[e]->f->offset, extras[e]->scalar, swap));
      if (wide)
        out.add_wide(load_scalar(pt + fx->f->offset, fx->scalar, swap), load_scalar(pt + fy->f->offset, fy->scalar, swap),
                     load_scalar(pt + fz->f->offset, fz->scalar, swap), in, c, ring, col);
      else
        out.add_at(load_float(pt + fx->f->offset, fx->scalar, swap), load_float(pt + fy->f->offset, fy->scalar, swap),
                   load_float(pt + fz->f->offset, fz->scalar, swap), in, c, ring, col);
    }
  }
  Status s = out.finish(where);
  if (!s.ok()) return s;
  if (r.cloud.rgb.empty() && !r.colors.empty() && r.colors.size() == r.cloud.size()) r.cloud.rgb = r.colors;
  return {};
}

// ---------------------------------------------------------------- the bag container

namespace {

constexpr char kBagMagic[] = "#ROSBAG V2.0\n";
constexpr std::size_t kBagMagicBytes = sizeof(kBagMagic) - 1;
constexpr std::uint64_t kMaxChunkBytes = 1ULL << 31;  // an uncompressed chunk (recorders write ~768 KiB)
// The most a compressed chunk can expand. LZ4: a match of 255 more bytes costs at least one
// more byte of input, so no LZ4 frame expands beyond 255:1 (the format's own bound). bzip2
// has no useful bound of its own (its run-length stage alone reaches ~45,000,000:1 on a
// single repeated byte); 2^16:1 is above any chunk a recorder writes (a 768 KiB chunk of one
// repeated byte, the most compressible there is, compresses to 46 bytes: 17,096:1) and keeps
// what a chunk of a few bytes may ask to be decompressed within a few hundred KiB.
constexpr std::uint64_t kMaxLz4Ratio = 255;
constexpr std::uint64_t kMaxBz2Ratio = 1ULL << 16;

/// One record: its header fields and where its data lies.
struct Record {
  std::uint64_t at = 0;  // offset of the record
  std::map<std::string, std::string_view> fields;
  std::uint64_t data = 0, data_len = 0, end = 0;
};

/// Reads the `name=value` fields (each after its u32 length) from byte `o` to `end` of `p`.
Status read_fields(const std::string& head, const std::uint8_t* p, std::uint64_t o, std::uint64_t end,
                   std::map<std::string, std::string_view>& fields) {
  while (o < end) {
    if (end - o < 4) return bad_data(head + " (a field length is cut)", o);
    std::uint32_t flen = 0;
    std::memcpy(&flen, p + o, 4);
    o += 4;
    if (flen > end - o) return bad_data(head + ": a field of " + std::to_string(flen) + " bytes runs past it", o);
    const std::string_view field(reinterpret_cast<const char*>(p + o), flen);
    const std::size_t eq = field.find('=');
    if (eq == std::string_view::npos) return bad_data(head + ": a field has no '='", o);
    fields[std::string(field.substr(0, eq))] = field.substr(eq + 1);
    o += flen;
  }
  return {};
}

/// Reads the record at `at` of the `size` bytes at `p`; `what` names the region in messages.
Status read_record(const std::string& path, const std::uint8_t* p, std::uint64_t size, std::uint64_t at, Record& rec,
                   const std::string& where) {
  rec = Record{};
  rec.at = at;
  auto u32 = [&](std::uint64_t o) {
    std::uint32_t v = 0;
    std::memcpy(&v, p + o, 4);
    return v;
  };
  const std::string head = msg(path, where + "record at byte " + std::to_string(at) + ": ");
  if (size - at < 4) return bad_data(head + "truncated (its header length is cut)", at);
  const std::uint64_t hlen = u32(at);
  if (hlen > size - at - 4)
    return bad_data(head + "truncated: header of " + std::to_string(hlen) + " bytes, " + std::to_string(size - at - 4) + " left", at);
  const std::uint64_t hend = at + 4 + hlen;
  Status s = read_fields(head + "corrupt header", p, at + 4, hend, rec.fields);
  if (!s.ok()) return s;
  if (size - hend < 4) return bad_data(head + "truncated (its data length is cut)", hend);
  rec.data_len = u32(hend);
  rec.data = hend + 4;
  if (rec.data_len > size - rec.data)
    return bad_data(head + "truncated: data of " + std::to_string(rec.data_len) + " bytes, " +
                        std::to_string(size - rec.data) + " left",
                    rec.data);
  rec.end = rec.data + rec.data_len;
  // a connection's data is a second list of fields (topic, type, md5sum, message_definition),
  // which the ROS bag library parses without checking its lengths against the data
  const auto op = rec.fields.find("op");
  if (op != rec.fields.end() && op->second == std::string_view("\x07", 1)) {
    std::map<std::string, std::string_view> conn;
    s = read_fields(head + "corrupt connection data", p, rec.data, rec.end, conn);
    if (!s.ok()) return s;
  }
  return {};
}

bool field_u8(const Record& r, const char* name, std::uint8_t& v) {
  const auto it = r.fields.find(name);
  if (it == r.fields.end() || it->second.size() != 1) return false;
  v = static_cast<std::uint8_t>(it->second[0]);
  return true;
}

template <typename T>
bool field_uint(const Record& r, const char* name, T& v) {
  const auto it = r.fields.find(name);
  if (it == r.fields.end() || it->second.size() != sizeof(T)) return false;
  std::memcpy(&v, it->second.data(), sizeof(T));
  return true;
}

/// Why a chunk's data did not decompress to its declared size.
struct Inflated {
  enum Kind { kOk, kShort, kLong, kCorrupt } kind = kOk;
  std::string why;  ///< kCorrupt: the decompressor's complaint
};

/// The output buffer, grown only as output arrives (never to a size the file declares up
/// front) and to at most `limit` bytes; false when it is full.
bool grow(std::vector<std::uint8_t>& out, std::size_t produced, std::size_t limit) {
  if (produced < out.size()) return true;
  if (out.size() >= limit) return false;
  out.resize(std::min<std::size_t>(limit, std::max<std::size_t>(out.size() * 2, 64 * 1024)));
  return true;
}

/// Decompresses a bz2 chunk's `n` bytes into `out` (resized to what came out), expecting
/// `declared` bytes: stops at one byte more.
Inflated inflate_bz2(const std::uint8_t* p, std::size_t n, std::size_t declared, std::vector<std::uint8_t>& out) {
  bz_stream z{};
  if (BZ2_bzDecompressInit(&z, 0, 0) != BZ_OK) return {Inflated::kCorrupt, "the bzip2 decoder did not start"};
  z.next_in = const_cast<char*>(reinterpret_cast<const char*>(p));  // bzlib's API is not const
  z.avail_in = static_cast<unsigned>(n);
  std::size_t produced = 0;
  out.clear();
  Inflated r;
  for (;;) {
    if (!grow(out, produced, declared + 1)) {
      r = {Inflated::kLong, ""};
      break;
    }
    z.next_out = reinterpret_cast<char*>(out.data() + produced);
    z.avail_out = static_cast<unsigned>(std::min<std::size_t>(out.size() - produced, 1U << 30));
    const unsigned before_in = z.avail_in, before_out = z.avail_out;
    const int ret = BZ2_bzDecompress(&z);
    produced += before_out - z.avail_out;
    if (ret == BZ_STREAM_END) {
      if (produced > declared) r = {Inflated::kLong, ""};
      else if (z.avail_in != 0)
        r = {Inflated::kCorrupt, std::to_string(z.avail_in) + " bytes follow the end of its bzip2 stream"};
      else if (produced < declared) r = {Inflated::kShort, ""};
      break;
    }
    if (ret != BZ_OK) {
      r = {Inflated::kCorrupt, ret == BZ_DATA_ERROR_MAGIC ? "not a bzip2 stream"
                               : ret == BZ_MEM_ERROR      ? "the bzip2 decoder ran out of memory"
                                                          : "corrupt bzip2 data"};
      break;
    }
    // all input taken and room left, or no progress at all: the stream needs bytes it lacks
    if ((z.avail_in == 0 && z.avail_out > 0) || (before_in == z.avail_in && before_out == z.avail_out)) {
      r = {Inflated::kCorrupt, "the bzip2 stream is cut short"};
      break;
    }
  }
  BZ2_bzDecompressEnd(&z);
  out.resize(std::min(produced, out.size()));
  return r;
}

/// The same for an LZ4 frame (the ROS bag library writes LZ4's frame format).
Inflated inflate_lz4(const std::uint8_t* p, std::size_t n, std::size_t declared, std::vector<std::uint8_t>& out) {
  LZ4F_dctx* ctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION)))
    return {Inflated::kCorrupt, "the LZ4 decoder did not start"};
  std::size_t in = 0, produced = 0;
  out.clear();
  Inflated r;
  for (;;) {
    if (!grow(out, produced, declared + 1)) {
      r = {Inflated::kLong, ""};
      break;
    }
    std::size_t dst = out.size() - produced, src = n - in;
    const std::size_t ret = LZ4F_decompress(ctx, out.data() + produced, &dst, p + in, &src, nullptr);
    if (LZ4F_isError(ret)) {
      r = {Inflated::kCorrupt, std::string("corrupt LZ4 data (") + LZ4F_getErrorName(ret) + ")"};
      break;
    }
    in += src;
    produced += dst;
    if (ret == 0) {  // the frame is complete
      if (produced > declared) r = {Inflated::kLong, ""};
      else if (in != n) r = {Inflated::kCorrupt, std::to_string(n - in) + " bytes follow the end of its LZ4 frame"};
      else if (produced < declared) r = {Inflated::kShort, ""};
      break;
    }
    if (src == 0 && dst == 0) {  // no input taken, no output made: the frame needs bytes it lacks
      r = {Inflated::kCorrupt, "the LZ4 frame is cut short"};
      break;
    }
  }
  LZ4F_freeDecompressionContext(ctx);
  out.resize(std::min(produced, out.size()));
  return r;
}

}  // namespace

Status check_bag_container(const std::string& path, const std::uint8_t* p, std::size_t size) {
  if (size < kBagMagicBytes || std::memcmp(p, kBagMagic, kBagMagicBytes) != 0) {
    if (size >= 9 && std::memcmp(p, "#ROSBAG V", 9) == 0)
      return bad_data(msg(path, "a ROS bag of another version than 2.0 (" +
                                    printable(std::string_view(reinterpret_cast<const char*>(p), std::min<std::size_t>(size, 13)).substr(1), 16) +
                                    "); lex3d reads bag format 2.0 (ROS 1)"));
    return bad_data(msg(path, "not a ROS bag (no \"#ROSBAG V2.0\" line)"), 0);
  }
  Record fh;
  Status s = read_record(path, p, size, kBagMagicBytes, fh, "file header ");
  if (!s.ok()) return s;
  std::uint8_t op = 0;
  std::uint64_t index_pos = 0;
  std::uint32_t conn_count = 0, chunk_count = 0;
  if (!field_u8(fh, "op", op) || op != 0x03 || !field_uint(fh, "index_pos", index_pos) ||
      !field_uint(fh, "conn_count", conn_count) || !field_uint(fh, "chunk_count", chunk_count))
    return bad_data(msg(path, "corrupt bag: the file header record lacks op 3, index_pos, conn_count or chunk_count"), kBagMagicBytes);
  if (index_pos == 0)
    return bad_data(msg(path, "the bag has no index (its recording was not closed): run 'rosbag reindex' on it first"));
  if (index_pos < fh.end || index_pos > size)
    return bad_data(msg(path, "truncated or corrupt bag: its index starts at byte " + std::to_string(index_pos) + " of " +
                                  std::to_string(size)),
                    size);
  // chunks (each followed by its index records) up to index_pos, then connections and chunk infos
  std::set<std::uint64_t> chunk_at;
  std::vector<std::uint64_t> message_at;  // the last chunk's message records (offsets in its data)
  std::vector<std::uint8_t> inflated;     // a compressed chunk's data
  std::map<std::uint64_t, std::map<std::uint32_t, std::uint32_t>> indexed;  // chunk -> connection -> messages
  std::set<std::uint32_t> listed;         // the index's connections
  std::set<std::uint64_t> described;      // chunks with a chunk info
  std::uint64_t last_chunk = 0;
  std::uint64_t at = fh.end;
  std::uint32_t connections = 0, chunk_infos = 0;
  while (at < size) {
    const bool in_index = at >= index_pos;
    if (!in_index && at > index_pos) break;
    Record rec;
    s = read_record(path, p, size, at, rec, "");
    if (!s.ok()) return s;
    if (!in_index && rec.end > index_pos)
      return bad_data(msg(path, "corrupt bag: the record at byte " + std::to_string(at) + " runs past the index at byte " +
                                    std::to_string(index_pos)),
                      at);
    if (!field_u8(rec, "op", op))
      return bad_data(msg(path, "corrupt bag: the record at byte " + std::to_string(at) + " has no op field"), at);
    const std::string where = "corrupt bag: the record at byte " + std::to_string(at) + " (op " + std::to_string(op) + ")";
    if (op == 0x05) {  // chunk
      std::uint32_t usize = 0;
      const auto comp = rec.fields.find("compression");
      if (comp == rec.fields.end() || !field_uint(rec, "size", usize))
        return bad_data(msg(path, where + " lacks compression or size"), at);
      const std::string_view compression = comp->second;
      if (compression != "none" && compression != "bz2" && compression != "lz4")
        return bad_data(msg(path, where + ": unknown chunk compression " + quoted(compression)), at);
      const std::string chunk = "chunk " + std::to_string(chunk_at.size() + 1) + " at byte " + std::to_string(at) + " (" +
                                std::string(compression) + ", " + std::to_string(rec.data_len) + " bytes)";
      if (usize > kMaxChunkBytes)
        return bad_data(msg(path, "corrupt bag: " + chunk + " declares " + std::to_string(usize) +
                                      " bytes uncompressed, more than the " + std::to_string(kMaxChunkBytes) +
                                      " a chunk may hold"),
                        at);
      if (compression == "none" && usize != rec.data_len)
        return bad_data(msg(path, "corrupt bag: " + chunk + " declares " + std::to_string(usize) + " bytes uncompressed"), at);
      // the declared size checked against what the compressed bytes can hold before anything is
      // allocated; the data then decompressed (its buffer grows with the output, not with the
      // declared size) and required to give exactly the declared size, since the ROS bag library
      // trusts it (its bz2 reader keeps a short chunk's stale tail)
      const std::uint8_t* body = p;
      std::uint64_t begin = rec.data, end = rec.end;
      if (compression != "none") {
        const std::uint64_t ratio = compression == "lz4" ? kMaxLz4Ratio : kMaxBz2Ratio;
        if (usize > ratio * rec.data_len)
          return bad_data(msg(path, "corrupt bag: " + chunk + " declares " + std::to_string(usize) +
                                        " bytes uncompressed, more than " + std::string(compression) + " expands " +
                                        std::to_string(rec.data_len) + " bytes to (at most " + std::to_string(ratio) + ":1)"),
                          at);
        const Inflated r = compression == "bz2" ? inflate_bz2(p + rec.data, rec.data_len, usize, inflated)
                                                : inflate_lz4(p + rec.data, rec.data_len, usize, inflated);
        if (r.kind == Inflated::kShort)
          return bad_data(msg(path, "corrupt bag: " + chunk + " decompresses to " + std::to_string(inflated.size()) +
                                        " bytes, fewer than the " + std::to_string(usize) + " its header declares"),
                          at);
        if (r.kind == Inflated::kLong)
          return bad_data(msg(path, "corrupt bag: " + chunk + " decompresses to more than the " + std::to_string(usize) +
                                        " bytes its header declares"),
                          at);
        if (r.kind == Inflated::kCorrupt)
          return bad_data(msg(path, "corrupt bag: " + chunk + " does not decompress: " + r.why), at);
        body = inflated.data();
        begin = 0;
        end = usize;
      }
      // its records: connections and messages that fit it; the messages' offsets kept for the
      // index data that follows
      message_at.clear();
      for (std::uint64_t in = begin; in < end;) {
        Record inner;
        s = read_record(path, body, end, in, inner, chunk + (compression == "none" ? ": " : ", decompressed: "));
        if (!s.ok()) return s;
        std::uint8_t inner_op = 0;
        if (!field_u8(inner, "op", inner_op) || (inner_op != 0x02 && inner_op != 0x07))
          return bad_data(msg(path, "corrupt bag: " + chunk + ": the record at data byte " + std::to_string(in - begin) +
                                        " is neither a message nor a connection"),
                          at);
        if (inner_op == 0x02) message_at.push_back(in - begin);
        in = inner.end;
      }
      chunk_at.insert(at);
      last_chunk = at;
    } else if (op == 0x04) {  // index data of the chunk before it: offsets of its message records
      std::uint32_t ver = 0, count = 0, conn = 0;
      if (last_chunk == 0 || !field_uint(rec, "ver", ver) || ver != 1 || !field_uint(rec, "count", count) ||
          !field_uint(rec, "conn", conn) || static_cast<std::uint64_t>(count) * 12U != rec.data_len)
        return bad_data(msg(path, where + ": index data that does not follow a chunk or does not hold its count"), at);
      if (!indexed[last_chunk].emplace(conn, count).second)
        return bad_data(msg(path, where + ": a second index data record of connection " + std::to_string(conn) +
                                      " for the chunk at byte " + std::to_string(last_chunk)),
                        at);
      for (std::uint32_t k = 0; k < count; ++k) {
        std::uint32_t off = 0;
        std::memcpy(&off, p + rec.data + 12ULL * k + 8, 4);
        if (!std::binary_search(message_at.begin(), message_at.end(), std::uint64_t{off}))
          return bad_data(msg(path, where + ": message offset " + std::to_string(off) +
                                        " is not the start of a message record of the chunk at byte " +
                                        std::to_string(last_chunk)),
                          at);
      }
    } else if (op == 0x07) {
      std::uint32_t conn = 0;
      if (!field_uint(rec, "conn", conn)) return bad_data(msg(path, where + ": a connection without its conn field"), at);
      if (in_index) {
        ++connections;
        if (!listed.insert(conn).second)
          return bad_data(msg(path, where + ": connection " + std::to_string(conn) + " listed twice in the index"), at);
      }
    } else if (op == 0x06) {  // chunk info: names a chunk seen above, and its messages a connection
      std::uint64_t pos = 0;
      std::uint32_t ver = 0, count = 0;
      if (!field_uint(rec, "chunk_pos", pos) || chunk_at.count(pos) == 0)
        return bad_data(msg(path, where + ": chunk info naming no chunk of the file"), at);
      if (!field_uint(rec, "ver", ver) || ver != 1 || !field_uint(rec, "count", count) ||
          static_cast<std::uint64_t>(count) * 8U != rec.data_len)
        return bad_data(msg(path, where + ": chunk info that does not hold its count"), at);
      if (!described.insert(pos).second)
        return bad_data(msg(path, where + ": a second chunk info for the chunk at byte " + std::to_string(pos)), at);
      // the ROS bag library reads as many index data records after the chunk as this lists
      // connections: a list that differs would drop messages without a word
      std::map<std::uint32_t, std::uint32_t> counts;
      for (std::uint32_t k = 0; k < count; ++k) {
        std::uint32_t conn = 0, n = 0;
        std::memcpy(&conn, p + rec.data + 8ULL * k, 4);
        std::memcpy(&n, p + rec.data + 8ULL * k + 4, 4);
        counts[conn] += n;
      }
      if (counts != indexed[pos] || counts.size() != count)
        return bad_data(msg(path, where + ": the chunk info of the chunk at byte " + std::to_string(pos) +
                                      " lists other connections or message counts than the index data after it"),
                        at);
      ++chunk_infos;
    } else if (op != 0x02) {
      return bad_data(msg(path, where + ": unknown record op"), at);
    }
    at = rec.end;
  }
  if (chunk_infos != chunk_count || connections != conn_count || chunk_at.size() != chunk_count)
    return bad_data(msg(path, "truncated or corrupt bag: the file header announces " + std::to_string(chunk_count) +
                                  " chunks and " + std::to_string(conn_count) + " connections, the file holds " +
                                  std::to_string(chunk_at.size()) + " chunks, " + std::to_string(chunk_infos) +
                                  " chunk infos and " + std::to_string(connections) + " connections in its index"),
                    size);
  for (const auto& [pos, counts] : indexed)
    for (const auto& [conn, n] : counts)
      if (listed.count(conn) == 0)
        return bad_data(msg(path, "corrupt bag: the index data of the chunk at byte " + std::to_string(pos) + " names connection " +
                                      std::to_string(conn) + ", which the index does not list (" + std::to_string(n) +
                                      " messages)"),
                        pos);
  return {};
}

}  // namespace lex3d::io::detail
