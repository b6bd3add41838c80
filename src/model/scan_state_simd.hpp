#pragma once
// Vector types and small inline helpers shared by the scan state's kernels
// (scan_state*.cpp): GCC and Clang vector extensions, each helper inlined into the
// AVX2 / AVX-512 / baseline builds of the kernel that calls it. Internal linkage: every
// translation unit keeps its own copies.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace lex3d::detail {
namespace {

// The hot loops below are compiled twice, for AVX2 and the baseline, and picked at load
// time; neither uses fused multiply-adds, so both give the same bits. The Gaussian sums
// have an AVX-512 build as well (twice the lanes an instruction); AVX-512 brings fused
// multiply-adds, which contraction is turned off to keep out.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define LEX3D_CLONES __attribute__((target_clones("avx2", "default")))
#define LEX3D_CLONES_512 __attribute__((target_clones("avx512f", "avx2", "default"), optimize("fp-contract=off")))
#else
#define LEX3D_CLONES
#define LEX3D_CLONES_512
#endif

// Eight floats or 32-bit integers as one value (GCC vector extensions: one AVX register in
// the AVX2 build, two SSE registers in the baseline one; the arithmetic is lane by lane).
// The helpers taking and returning them are inlined into each build (hence no ABI to keep).
#if defined(__clang__)
#pragma clang diagnostic ignored "-Wpsabi"
#elif defined(__GNUC__)
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
typedef float V8f __attribute__((vector_size(32)));
typedef std::int32_t V8i __attribute__((vector_size(32)));

inline V8f load8(const float* p) {
  V8f v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline V8f max8(V8f a, V8f b) { return a < b ? b : a; }
// Lane 0 copied to all lanes (a broadcast, not eight inserts).
// The lanes of v picked by eight indices, with each compiler's builtin.
#if defined(__clang__)
#define LEX3D_SHUFFLE8(v, ...) __builtin_shufflevector(v, v, __VA_ARGS__)
#else
#define LEX3D_SHUFFLE8(v, ...) __builtin_shuffle(v, V8i{__VA_ARGS__})
#endif
inline V8f splat8(float x) { return LEX3D_SHUFFLE8(V8f{x}, 0, 0, 0, 0, 0, 0, 0, 0); }
inline V8i splat8i(std::int32_t x) { return LEX3D_SHUFFLE8(V8i{x}, 0, 0, 0, 0, 0, 0, 0, 0); }
// Squared distances of eight points to the box [lo, hi] (0 inside).
inline V8f box_gap2_8(V8f qx, V8f qy, V8f qz, const float* lo, const float* hi) {
  const V8f zero = splat8(0.0F);
  const V8f ox = max8(max8(splat8(lo[0]) - qx, qx - splat8(hi[0])), zero);
  const V8f oy = max8(max8(splat8(lo[1]) - qy, qy - splat8(hi[1])), zero);
  const V8f oz = max8(max8(splat8(lo[2]) - qz, qz - splat8(hi[2])), zero);
  return ox * ox + oy * oy + oz * oz;
}
typedef long long V4ll __attribute__((vector_size(32)));
inline bool any8(V8i m) {
  const auto q = reinterpret_cast<V4ll>(m);
  return ((q[0] | q[1]) | (q[2] | q[3])) != 0;
}
// Sixteen lanes: two groups of eight (one register in the AVX-512 build).
typedef float V16f __attribute__((vector_size(64)));
typedef std::int32_t V16i __attribute__((vector_size(64)));
inline V16f twice8(V8f v) { return __builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7); }
// a in the low eight lanes, b in the high eight (two broadcasts and an insert).
inline V16f splat2(float a, float b) {
  return __builtin_shufflevector(splat8(a), splat8(b), 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
}
inline V8f low8(V16f v) { return __builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7); }
inline V8f high8(V16f v) { return __builtin_shufflevector(v, v, 8, 9, 10, 11, 12, 13, 14, 15); }
inline V16f mask16(V16f v, V16i m) { return reinterpret_cast<V16f>(reinterpret_cast<V16i>(v) & m); }

// e^x for x in [-87, 0] on each lane of V (eight or sixteen floats; Cody-Waite reduction,
// the Cephes polynomial; relative error about 2e-7), branch-free (the caller keeps x in
// range). Every lane goes through the same operations whatever the width.
template <class V>
inline V exp_neg(V x) {
  using VI = decltype(x < x);
  const float kRound = 12582912.0F;
  const V n = (x * 1.44269504088896341F + kRound) - kRound;
  const V r = (x - n * 0.693359375F) - n * -2.12194440e-4F;
  V y = V{} + 1.9875691500E-4F;
  y = y * r + 1.3981999507E-3F;
  y = y * r + 8.3334519073E-3F;
  y = y * r + 4.1665795894E-2F;
  y = y * r + 1.6666665459E-1F;
  y = y * r + 5.0000001201E-1F;
  y = y * (r * r) + r + 1.0F;
  const VI bits = (__builtin_convertvector(n, VI) + 127) << 23;
  return y * reinterpret_cast<V>(bits);
}

// The bounding box (lo, hi) of points [p, e) of (x, y, z), e > p.
inline void box_of(const float* x, const float* y, const float* z, std::size_t p, std::size_t e, float lo[3],
                   float hi[3]) {
  lo[0] = hi[0] = x[p];
  lo[1] = hi[1] = y[p];
  lo[2] = hi[2] = z[p];
  for (std::size_t q = p + 1; q < e; ++q) {
    lo[0] = std::min(lo[0], x[q]);
    lo[1] = std::min(lo[1], y[q]);
    lo[2] = std::min(lo[2], z[q]);
    hi[0] = std::max(hi[0], x[q]);
    hi[1] = std::max(hi[1], y[q]);
    hi[2] = std::max(hi[2], z[q]);
  }
}

// The lanes set in eight 0/-1 lanes as the bits of a byte (lane l, bit l): three
// halvings of the lanes, no lane taken out on its own.
inline unsigned lane_bits8(V8i m) {
  V8i t = m & V8i{1, 2, 4, 8, 16, 32, 64, 128};
  t |= LEX3D_SHUFFLE8(t, 4, 5, 6, 7, 0, 1, 2, 3);
  t |= LEX3D_SHUFFLE8(t, 2, 3, 0, 1, 6, 7, 4, 5);
  t |= LEX3D_SHUFFLE8(t, 1, 0, 3, 2, 5, 4, 7, 6);
  return static_cast<unsigned>(t[0]);
}

// For each byte of lane bits: the set lanes, lowest first (the rest of the eight
// unused), and how many there are.
struct LaneLists {
  std::int32_t lanes[256][8];  // 32-bit: loaded as one vector, with no widening
  std::uint8_t count[256];
};
constexpr LaneLists make_lane_lists() {
  LaneLists t{};
  for (unsigned m = 0; m < 256; ++m) {
    unsigned n = 0;
    for (unsigned l = 0; l < 8; ++l)
      if ((m >> l) & 1U) t.lanes[m][n++] = static_cast<std::int32_t>(l);
    t.count[m] = static_cast<std::uint8_t>(n);
  }
  return t;
}
constexpr LaneLists kLaneLists = make_lane_lists();

// Appends base + l for each lane l set in `bits` to list[n...] (eight values written:
// the list needs room for eight past its end); returns the new length.
inline std::size_t append_lanes(std::uint32_t* list, std::size_t n, unsigned bits, std::uint32_t base) {
  V8i l;
  std::memcpy(&l, kLaneLists.lanes[bits], sizeof l);
  const V8i v = l + splat8i(static_cast<std::int32_t>(base));
  std::memcpy(list + n, &v, sizeof v);
  return n + kLaneLists.count[bits];
}

// Makes v at least n long. The scratch arrays below are reused from one feature to the
// next with different lengths; resize() to a smaller then a larger length zero-fills the
// difference every time, where growing only does it once (every element read is written
// first).
template <class V>
inline void grow(V& v, std::size_t n) {
  if (v.size() < n) v.resize(n);
}

// Coordinate r of T * (x, y, z) as Eigen's Isometry3f * Vector3f computes it, m being T's 4x4
// matrix (column-major): ((T(r,0) x + T(r,1) y) + T(r,2) z) + T(r,3); for eight points at once
// and for one.
inline V8f frame_row(const float* m, int r, V8f x, V8f y, V8f z) {
  return ((splat8(m[r]) * x + splat8(m[4 + r]) * y) + splat8(m[8 + r]) * z) + splat8(m[12 + r]);
}
inline float frame_row(const float* m, int r, float x, float y, float z) {
  return ((m[r] * x + m[4 + r] * y) + m[8 + r] * z) + m[12 + r];
}

}  // namespace
}  // namespace lex3d::detail
