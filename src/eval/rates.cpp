// Compression rates with the byte costs of ruhnke2010 §IV, and the same after deflate.
//
// Byte costs (ruhnke2010 §IV, the alphabet included in the model):
//   raw   = 12 bytes a point of the input (3 float32),
//   model = 12 bytes a point of every word of the alphabet
//         + 24 bytes a word instance (its transform, 6 float32)
//         +  4 bytes a word instance (its word reference, an int32).
//
// Deflated sizes: both sides are serialised as flat little-endian arrays and
// compressed with zlib's compress2 at level 9 (a zlib stream: 2-byte header,
// deflate data, 4-byte Adler-32); the byte counts are the stream sizes.
//   raw stream:   every input point as float32 x, y, z (12 bytes a point).
//   model stream: the alphabet, word by word, every word point as float32 x, y, z;
//                 then every instance as int32 word id, float32 tx, ty, tz (the
//                 translation) and float32 rx, ry, rz (the rotation as a rotation
//                 vector: unit axis times angle in radians, angle in [0, pi]),
//                 28 bytes an instance.
// The uncompressed model stream is exactly model_bytes long and the raw stream
// raw_bytes long (word sizes are not stored, as in the paper's cost).
// With no input points both rates are 0 (rather than a division by zero).

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include <zlib.h>

#include <Eigen/Geometry>

#include "lex3d/eval/metrics.hpp"

namespace lex3d::eval {
namespace {

constexpr std::uint64_t kPointBytes = 12;     // float32 x y z
constexpr std::uint64_t kTransformBytes = 24;  // 6 float32
constexpr std::uint64_t kWordRefBytes = 4;     // int32

void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xFFU));
  out.push_back(static_cast<std::uint8_t>((v >> 8U) & 0xFFU));
  out.push_back(static_cast<std::uint8_t>((v >> 16U) & 0xFFU));
  out.push_back(static_cast<std::uint8_t>((v >> 24U) & 0xFFU));
}

void put_f32(std::vector<std::uint8_t>& out, float f) {
  static_assert(sizeof(float) == 4, "float32 expected");
  std::uint32_t bits = 0;
  std::memcpy(&bits, &f, sizeof bits);
  put_u32(out, bits);
}

void put_xyz(std::vector<std::uint8_t>& out, const Eigen::Vector3f& p) {
  put_f32(out, p.x());
  put_f32(out, p.y());
  put_f32(out, p.z());
}

/// Size of the zlib stream (compress2, level 9) of `bytes`.
std::uint64_t deflated_size(const std::vector<std::uint8_t>& bytes) {
  uLongf out_len = compressBound(static_cast<uLong>(bytes.size()));
  std::vector<Bytef> out(out_len);
  const int rc = compress2(out.data(), &out_len, bytes.data(), static_cast<uLong>(bytes.size()), 9);
  if (rc != Z_OK) throw std::runtime_error("compression_rates: zlib compress2 failed (" + std::to_string(rc) + ")");
  return static_cast<std::uint64_t>(out_len);
}

}  // namespace

RateResult compression_rates(const Cloud& input, const std::vector<std::vector<Eigen::Vector3f>>& words,
                             const std::vector<std::uint32_t>& instance_word,
                             const std::vector<Pose>& instance_pose) {
  if (instance_word.size() != instance_pose.size())
    throw std::invalid_argument("compression_rates: instance_word (" + std::to_string(instance_word.size()) +
                                ") and instance_pose (" + std::to_string(instance_pose.size()) +
                                ") must have the same size");
  for (std::size_t i = 0; i < instance_word.size(); ++i)
    if (instance_word[i] >= words.size() || instance_word[i] > 0x7FFFFFFFU)
      throw std::invalid_argument("compression_rates: instance_word[" + std::to_string(i) + "] = " +
                                  std::to_string(instance_word[i]) + " must be < the number of words (" +
                                  std::to_string(words.size()) + ")");

  std::uint64_t alphabet_points = 0;
  for (const auto& w : words) alphabet_points += w.size();
  const std::uint64_t instances = instance_word.size();

  RateResult r;
  r.raw_bytes = kPointBytes * input.points.size();
  r.model_bytes = kPointBytes * alphabet_points + (kTransformBytes + kWordRefBytes) * instances;
  r.rate = r.raw_bytes == 0 ? 0.0 : static_cast<double>(r.model_bytes) / static_cast<double>(r.raw_bytes);

  std::vector<std::uint8_t> raw;
  raw.reserve(static_cast<std::size_t>(r.raw_bytes));
  for (const auto& p : input.points) put_xyz(raw, p);

  std::vector<std::uint8_t> model;
  model.reserve(static_cast<std::size_t>(r.model_bytes));
  for (const auto& w : words)
    for (const auto& p : w) put_xyz(model, p);
  for (std::size_t i = 0; i < instance_word.size(); ++i) {
    put_u32(model, instance_word[i]);  // an int32: the range was checked above
    const Pose& T = instance_pose[i];
    const Eigen::Vector3d t = T.translation();
    const Eigen::AngleAxisd aa(T.linear());
    const Eigen::Vector3d rv = aa.angle() * aa.axis();
    for (int k = 0; k < 3; ++k) put_f32(model, static_cast<float>(t[k]));
    for (int k = 0; k < 3; ++k) put_f32(model, static_cast<float>(rv[k]));
  }

  r.raw_gzip_bytes = deflated_size(raw);
  r.model_gzip_bytes = deflated_size(model);
  r.gzip_rate = input.points.empty() ? 0.0
                                     : static_cast<double>(r.model_gzip_bytes) / static_cast<double>(r.raw_gzip_bytes);
  return r;
}

}  // namespace lex3d::eval
