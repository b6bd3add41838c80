#include "model/scan_state.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include "lex3d/core/parallel.hpp"

namespace lex3d::detail {

PackedWord::PackedWord(const Word& word) {
  const std::size_t n = word.points.size();
  x.resize(n);
  y.resize(n);
  z.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    x[i] = word.points[i].x();
    y[i] = word.points[i].y();
    z[i] = word.points[i].z();
  }
  // Padding: far points that no loop counts (padded() of them are read).
  const std::size_t npad = (n + 7) / 8 * 8;
  xp.assign(npad, 1e9F);
  yp.assign(npad, 1e9F);
  zp.assign(npad, 1e9F);
  std::copy(x.begin(), x.end(), xp.begin());
  std::copy(y.begin(), y.end(), yp.begin());
  std::copy(z.begin(), z.end(), zp.begin());
  if (n > 0) {
    lo = hi = word.points.front();
    for (const auto& p : word.points) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
}

namespace {

std::vector<PackedWord> pack(const Alphabet& alphabet) {
  std::vector<PackedWord> out;
  out.reserve(alphabet.size());
  for (const auto& w : alphabet.words) out.emplace_back(w);
  return out;
}

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

// Σ_p exp(-d²·a) over the word points within reach of each entry (0 when none), times
// norm when not 0 (in double, rounded to float), for the n entries of a feature (a and
// norm are per scan point: scale[idx[k]]).
// Word arrays hold np points padded to npad, a multiple of 8, with far points; the sum
// keeps eight lanes (point p in lane p % 8), each adding its blocks of eight points in
// order, the lanes then added pairwise, so the SSE, AVX2 and AVX-512 builds give the
// same bits.
// A block with no point in reach would add only zeros and is left out (about 60 % of
// them on KITTI). Passes with no data-dependent branch in their inner loops: the entries
// within reach of the word's bounding box; per block, those of them within reach of the
// block's bounding box (eight entries a test), then their exponentials added into each
// entry's lanes (blocks in order).
LEX3D_CLONES_512 void gaussian_sums(const float* lx, const float* ly, const float* lz, const float* reach2,
                                    const PointScale* scale, std::size_t n, const float* wx, const float* wy,
                                    const float* wz, std::size_t np, std::size_t npad, const float* lo,
                                    const float* hi, const std::uint32_t* idx, float* out) {
  // Scratch as plain floats, read and written without alignment assumptions.
  thread_local std::vector<float> cx, cy, cz, cr, cna, acc;
  thread_local std::vector<double> cnorm;
  thread_local std::vector<std::uint32_t> live, cand;
  const std::size_t nb = npad / 8;
  const std::size_t n8 = (n + 7) / 8 * 8;
  if (live.size() < n8 + 8) {
    live.resize(n8 + 8);
    cand.resize(n8 + 8);
    cx.resize(n8 + 1);
    cy.resize(n8 + 1);
    cz.resize(n8 + 1);
    cr.resize(n8 + 1);
    cna.resize(n8 + 1);
    cnorm.resize(n8 + 1);
    acc.resize(8 * (n8 + 1));
  }
  std::fill(out, out + n, 0.0F);
  // The entries within 3σ of the word's bounding box (the others get nothing).
  std::size_t nl = 0;
  std::size_t k0 = 0;
  for (; k0 + 8 <= n; k0 += 8) {
    const V8f qx = load8(lx + k0), qy = load8(ly + k0), qz = load8(lz + k0);
    const V8i in = box_gap2_8(qx, qy, qz, lo, hi) <= load8(reach2 + k0);
    nl = append_lanes(live.data(), nl, lane_bits8(in), static_cast<std::uint32_t>(k0));
    // The scales of the live entries are read next, at scattered points of the scan
    // (most of them not in cache): their loads start here, overlapping this pass.
    for (std::size_t l = 0; l < 8; ++l) __builtin_prefetch(&scale[idx[k0 + l]]);
  }
  for (; k0 < n; ++k0) {
    const float qx = lx[k0], qy = ly[k0], qz = lz[k0];
    const float ox = std::max(std::max(lo[0] - qx, qx - hi[0]), 0.0F);
    const float oy = std::max(std::max(lo[1] - qy, qy - hi[1]), 0.0F);
    const float oz = std::max(std::max(lo[2] - qz, qz - hi[2]), 0.0F);
    live[nl] = static_cast<std::uint32_t>(k0);
    nl += ox * ox + oy * oy + oz * oz > reach2[k0] ? 0 : 1;
  }
  if (nl == 0) return;
  // The live entries side by side, padded to eight with entries nothing reaches, and one
  // more such entry after them (the spare of the pairs below).
  const std::size_t nl8 = (nl + 7) / 8 * 8;
  for (std::size_t u = 0; u <= nl8; ++u) {
    const std::size_t k = live[u < nl ? u : 0];
    cx[u] = lx[k];
    cy[u] = ly[k];
    cz[u] = lz[k];
    cr[u] = u < nl ? reach2[k] : -1.0F;
    cna[u] = -scale[idx[k]].a;
    cnorm[u] = scale[idx[k]].norm;
  }
  std::fill(acc.begin(), acc.begin() + static_cast<std::ptrdiff_t>(8 * (nl8 + 1)), 0.0F);
  for (std::size_t b = 0; b < nb; ++b) {
    const std::size_t p = 8 * b;
    if (p >= np) break;  // only far padding from here on
    float blo[3], bhi[3];
    box_of(wx, wy, wz, p, std::min(p + 8, np), blo, bhi);
    // Live entries within reach of the block's bounding box (no squared distance to a
    // point of the block is below the one to its box).
    std::size_t nc = 0;
    for (std::size_t u = 0; u < nl8; u += 8) {
      const V8f qx = load8(cx.data() + u), qy = load8(cy.data() + u), qz = load8(cz.data() + u);
      const V8i near = box_gap2_8(qx, qy, qz, blo, bhi) <= load8(cr.data() + u);
      nc = append_lanes(cand.data(), nc, lane_bits8(near), static_cast<std::uint32_t>(u));
    }
    // The exponentials go straight into the entry's lanes, in block order, for two
    // candidates at a time (sixteen lanes: one AVX-512 register; an odd count ends with
    // the spare entry, which nothing reaches). A candidate none of whose points is in
    // reach adds eight zeros, which changes no sum (they are +0 and the sums start at
    // +0): cheaper than a branch, or than storing the exponents for a pass of their own.
    if (nc % 2 != 0) cand[nc++] = static_cast<std::uint32_t>(nl8);
    const V8f bx8 = load8(wx + p), by8 = load8(wy + p), bz8 = load8(wz + p);
    const V16f bx = twice8(bx8), by = twice8(by8), bz = twice8(bz8);
    for (std::size_t c = 0; c < nc; c += 2) {
      const std::uint32_t u0 = cand[c], u1 = cand[c + 1];
      const V16f dx = bx - splat2(cx[u0], cx[u1]), dy = by - splat2(cy[u0], cy[u1]),
                 dz = bz - splat2(cz[u0], cz[u1]);
      const V16f d2 = dx * dx + dy * dy + dz * dz;
      // Points beyond reach: d² and the result masked to 0 (as bits).
      const V16i mk = d2 <= splat2(cr[u0], cr[u1]);
      const V16f e = mask16(exp_neg(mask16(d2, mk) * splat2(cna[u0], cna[u1])), mk);
      float* const s0 = acc.data() + 8 * static_cast<std::size_t>(u0);
      float* const s1 = acc.data() + 8 * static_cast<std::size_t>(u1);
      const V8f v0 = load8(s0) + low8(e);
      std::memcpy(s0, &v0, sizeof v0);
      const V8f v1 = load8(s1) + high8(e);
      std::memcpy(s1, &v1, sizeof v1);
    }
  }
  for (std::size_t u = 0; u < nl; ++u) {
    const V8f v = load8(acc.data() + 8 * u);
    const float sum = ((v[0] + v[1]) + (v[2] + v[3])) + ((v[4] + v[5]) + (v[6] + v[7]));
    // A zero sum stays +0 (whatever the norm): the product's bits masked, as a branch
    // on the sum would often be mispredicted.
    const float scaled = static_cast<float>(static_cast<double>(sum) * cnorm[u]);
    std::uint32_t bits;
    std::memcpy(&bits, &scaled, sizeof bits);
    bits &= 0U - static_cast<std::uint32_t>(sum != 0.0F);
    std::memcpy(out + live[u], &bits, sizeof bits);
  }
}

// The smallest and the largest of eight floats (none NaN), halving the lanes three
// times: min and max pick one of their operands, so any order gives the same values
// (up to the sign of a zero, which the squared gaps between boxes do not see).
inline void min_max8(V8f v, float& lo, float& hi) {
  const V8f s4 = LEX3D_SHUFFLE8(v, 4, 5, 6, 7, 0, 1, 2, 3);
  V8f mn = v < s4 ? v : s4, mx = max8(v, s4);
  const V8f n2 = LEX3D_SHUFFLE8(mn, 2, 3, 0, 1, 6, 7, 4, 5);
  const V8f x2 = LEX3D_SHUFFLE8(mx, 2, 3, 0, 1, 6, 7, 4, 5);
  mn = mn < n2 ? mn : n2;
  mx = max8(mx, x2);
  const V8f n1 = LEX3D_SHUFFLE8(mn, 1, 0, 3, 2, 5, 4, 7, 6);
  const V8f x1 = LEX3D_SHUFFLE8(mx, 1, 0, 3, 2, 5, 4, 7, 6);
  mn = mn < n1 ? mn : n1;
  mx = max8(mx, x1);
  lo = mn[0];
  hi = mx[0];
}

// The bounding boxes of the nt targets (tx, ty, tz) in runs of eight, as six arrays of
// nr8 values (lo x, y, z, hi x, y, z; nr8: the runs rounded up to a multiple of 8, the
// extra ones empty boxes far away); returns nr8. A full run's box comes from one vector
// per axis (a chain of seven scalar min / max steps per axis was most of the time).
LEX3D_CLONES std::size_t run_boxes(const float* tx, const float* ty, const float* tz, std::size_t nt,
                                   std::vector<float>& box) {
  const std::size_t nr = (nt + 7) / 8;
  const std::size_t nr8 = (nr + 7) / 8 * 8;
  box.assign(6 * nr8, 1e9F);
  float* const lo[3] = {box.data(), box.data() + nr8, box.data() + 2 * nr8};
  float* const hi[3] = {box.data() + 3 * nr8, box.data() + 4 * nr8, box.data() + 5 * nr8};
  const float* const t[3] = {tx, ty, tz};
  for (std::size_t r = 0; r < nr; ++r) {
    const std::size_t t0 = 8 * r, t1 = std::min(t0 + 8, nt);  // the real targets of the run
    for (int a = 0; a < 3; ++a) {
      float l = t[a][t0], h = t[a][t0];
      if (t1 == t0 + 8) {
        min_max8(load8(t[a] + t0), l, h);
      } else {
        for (std::size_t u = t0 + 1; u < t1; ++u) {
          l = std::min(l, t[a][u]);
          h = std::max(h, t[a][u]);
        }
      }
      lo[a][r] = l;
      hi[a][r] = h;
    }
  }
  return nr8;
}

// For each of the npad word points (mx, my, mz), np of them real (the rest padding that
// matches nothing), the first target strictly nearest within reach (match -1 when none).
// The targets are padded to a multiple of 8 with far points (on the other side from the
// word's padding), their runs' boxes made by run_boxes. Eight word points at a time, held
// in registers while the targets pass, with selects done on bits. The targets go by in
// runs of eight (in order); a run whose bounding box is at least reach from that of the
// word points in hand is left out: no squared distance between one of its targets and one
// of those points is below that of the boxes (the rounded differences keep their order),
// so none of its targets could be taken.
LEX3D_CLONES void nearest_targets(const float* tx, const float* ty, const float* tz, const float* rbox, std::size_t nr8,
                                  const float* mx, const float* my, const float* mz, std::size_t np, std::size_t npad,
                                  float reach2, float* best, std::int32_t* match) {
  thread_local std::vector<std::uint32_t> runs;
  if (runs.size() < nr8) runs.resize(nr8);
  // The runs that may hold a target within reach of the real word points [p, p + len);
  // returns how many (in runs).
  const auto near_runs = [&](std::size_t p, std::size_t len) {
    const std::size_t e = std::min(p + len, np);
    if (e <= p) return std::size_t{0};  // padding only
    float lo[3], hi[3];
    box_of(mx, my, mz, p, e, lo, hi);
    std::size_t count = 0;
    const V8f zero = splat8(0.0F);
    for (std::size_t r = 0; r < nr8; r += 8) {
      const V8f gx = max8(max8(load8(rbox + r) - splat8(hi[0]), splat8(lo[0]) - load8(rbox + 3 * nr8 + r)), zero);
      const V8f gy = max8(max8(load8(rbox + nr8 + r) - splat8(hi[1]), splat8(lo[1]) - load8(rbox + 4 * nr8 + r)), zero);
      const V8f gz = max8(max8(load8(rbox + 2 * nr8 + r) - splat8(hi[2]), splat8(lo[2]) - load8(rbox + 5 * nr8 + r)), zero);
      const V8i near = gx * gx + gy * gy + gz * gz < splat8(reach2);
      for (std::size_t l = 0; l < 8; ++l) {
        runs[count] = static_cast<std::uint32_t>(r + l);
        count -= static_cast<std::size_t>(static_cast<std::ptrdiff_t>(near[l]));
      }
    }
    return count;
  };
  const V8i zero8 = {0, 0, 0, 0, 0, 0, 0, 0};
  std::size_t p = 0;
  // Two blocks at a time: two independent chains of compare and select.
  for (; p + 16 <= npad; p += 16) {
    const V8f ax = load8(mx + p), ay = load8(my + p), az = load8(mz + p);
    const V8f bx = load8(mx + p + 8), by = load8(my + p + 8), bz = load8(mz + p + 8);
    V8f abst = splat8(reach2), bbst = abst;
    V8i amt = zero8 - 1, bmt = amt;
    const std::size_t nrun = near_runs(p, 16);
    for (std::size_t i = 0; i < nrun; ++i) {
      const std::size_t t0 = 8 * std::size_t{runs[i]};
      for (std::size_t t = t0; t < t0 + 8; ++t) {
        const V8f x = splat8(tx[t]), y = splat8(ty[t]), z = splat8(tz[t]);
        const V8i ti = splat8i(static_cast<std::int32_t>(t));
        const V8f adx = x - ax, ady = y - ay, adz = z - az;
        const V8f bdx = x - bx, bdy = y - by, bdz = z - bz;
        const V8f ad2 = adx * adx + ady * ady + adz * adz;
        const V8f bd2 = bdx * bdx + bdy * bdy + bdz * bdz;
        const V8i am = ad2 < abst, bm = bd2 < bbst;
        abst = reinterpret_cast<V8f>((reinterpret_cast<V8i>(abst) & ~am) | (reinterpret_cast<V8i>(ad2) & am));
        bbst = reinterpret_cast<V8f>((reinterpret_cast<V8i>(bbst) & ~bm) | (reinterpret_cast<V8i>(bd2) & bm));
        amt = (amt & ~am) | (ti & am);
        bmt = (bmt & ~bm) | (ti & bm);
      }
    }
    std::memcpy(best + p, &abst, sizeof abst);
    std::memcpy(match + p, &amt, sizeof amt);
    std::memcpy(best + p + 8, &bbst, sizeof bbst);
    std::memcpy(match + p + 8, &bmt, sizeof bmt);
  }
  for (; p < npad; p += 8) {
    const V8f px = load8(mx + p), py = load8(my + p), pz = load8(mz + p);
    V8f bst = splat8(reach2);
    V8i mt = zero8 - 1;
    const std::size_t nrun = near_runs(p, 8);
    for (std::size_t i = 0; i < nrun; ++i) {
      const std::size_t t0 = 8 * std::size_t{runs[i]};
      for (std::size_t t = t0; t < t0 + 8; ++t) {
        const V8f dx = splat8(tx[t]) - px, dy = splat8(ty[t]) - py, dz = splat8(tz[t]) - pz;
        const V8f d2 = dx * dx + dy * dy + dz * dz;
        const V8i m = d2 < bst;
        bst = reinterpret_cast<V8f>((reinterpret_cast<V8i>(bst) & ~m) | (reinterpret_cast<V8i>(d2) & m));
        mt = (mt & ~m) | (splat8i(static_cast<std::int32_t>(t)) & m);
      }
    }
    std::memcpy(best + p, &bst, sizeof bst);
    std::memcpy(match + p, &mt, sizeof mt);
  }
}

// ICP targets: copies to (fx, fy, fz), in order, the n points (lx, ly, lz) within `margin`
// of the box [wlo, whi] on every axis whose squared distance to the box [slo, shi] is
// below reach2; returns how many. Eight points at a time (the tail one by one).
LEX3D_CLONES std::size_t select_targets(const float* lx, const float* ly, const float* lz, std::size_t n,
                                        const float* wlo, const float* whi, float margin, const float* slo,
                                        const float* shi, float reach2, float* fx, float* fy, float* fz) {
  std::size_t nf = 0;
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    const V8f qx = load8(lx + k), qy = load8(ly + k), qz = load8(lz + k);
    const V8f mv = splat8(margin);
    const V8i keep = (box_gap2_8(qx, qy, qz, slo, shi) < splat8(reach2)) & (splat8(wlo[0]) - qx <= mv) &
                     (qx - splat8(whi[0]) <= mv) & (splat8(wlo[1]) - qy <= mv) & (qy - splat8(whi[1]) <= mv) &
                     (splat8(wlo[2]) - qz <= mv) & (qz - splat8(whi[2]) <= mv);
    if (!any8(keep)) continue;
    for (std::size_t l = 0; l < 8; ++l) {
      fx[nf] = lx[k + l];
      fy[nf] = ly[k + l];
      fz[nf] = lz[k + l];
      nf -= static_cast<std::size_t>(static_cast<std::ptrdiff_t>(keep[l]));
    }
  }
  for (; k < n; ++k) {
    const float qx = lx[k], qy = ly[k], qz = lz[k];
    const float ox = std::max(std::max(slo[0] - qx, qx - shi[0]), 0.0F);
    const float oy = std::max(std::max(slo[1] - qy, qy - shi[1]), 0.0F);
    const float oz = std::max(std::max(slo[2] - qz, qz - shi[2]), 0.0F);
    fx[nf] = qx;
    fy[nf] = qy;
    fz[nf] = qz;
    nf += (ox * ox + oy * oy + oz * oz < reach2 && wlo[0] - qx <= margin && qx - whi[0] <= margin &&
           wlo[1] - qy <= margin && qy - whi[1] <= margin && wlo[2] - qz <= margin && qz - whi[2] <= margin)
              ? 1
              : 0;
  }
  return nf;
}

// Word choice by fit: sets sup[p] when word point p is within σ of some entry and
// returns how many entries have a word point within σ (sig2: σ² of each entry). Word
// points outside, entries inside, so the inner loop runs over many entries and vectorises.
LEX3D_CLONES std::size_t fit_counts(const float* lx, const float* ly, const float* lz, const float* sig2, std::size_t n,
                                    const float* wx, const float* wy, const float* wz, std::size_t np,
                                    std::int32_t* hit, std::int32_t* sup) {
  for (std::size_t k = 0; k < n; ++k) hit[k] = 0;
  for (std::size_t p = 0; p < np; ++p) {
    const float px = wx[p], py = wy[p], pz = wz[p];
    std::int32_t any = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const float dx = px - lx[k], dy = py - ly[k], dz = pz - lz[k];
      const std::int32_t m = (dx * dx + dy * dy + dz * dz <= sig2[k]) ? 1 : 0;
      hit[k] |= m;
      any |= m;
    }
    sup[p] = any;
  }
  std::size_t explained = 0;
  for (std::size_t k = 0; k < n; ++k) explained += static_cast<std::size_t>(hit[k]);
  return explained;
}

// v where m is all ones, +0 where it is zero (a select on bits: loops using it vectorise).
inline float mask(float v, std::uint32_t m) {
  std::uint32_t b;
  std::memcpy(&b, &v, sizeof b);
  b &= m;
  std::memcpy(&v, &b, sizeof v);
  return v;
}

// 1 when an entry at (x, y, z) with σ² s2 may be within its σ of the box with centre c and
// half sizes h, else 0. The margin (0.2 % of σ² and 1e-8 m²) exceeds the rounding of the
// box's centre and half sizes, so no entry that could pass the fit test with a point in
// the box gets 0.
inline std::int32_t near_box(float x, float y, float z, float s2, const float* c, const float* h) {
  float ox = std::fabs(x - c[0]) - h[0];
  float oy = std::fabs(y - c[1]) - h[1];
  float oz = std::fabs(z - c[2]) - h[2];
  // max(o, 0) as bits, so that the loops using this vectorise.
  ox = mask(ox, static_cast<std::uint32_t>(-static_cast<std::int32_t>(ox > 0.0F)));
  oy = mask(oy, static_cast<std::uint32_t>(-static_cast<std::int32_t>(oy > 0.0F)));
  oz = mask(oz, static_cast<std::uint32_t>(-static_cast<std::int32_t>(oz > 0.0F)));
  return (ox * ox + oy * oy + oz * oz <= s2 * 1.002F + 1e-8F) ? 1 : 0;
}
inline void box_centre(const float* blo, const float* bhi, float* c, float* h) {
  for (int a = 0; a < 3; ++a) {
    c[a] = 0.5F * (blo[a] + bhi[a]);
    h[a] = 0.5F * (bhi[a] - blo[a]);
  }
}

// keep[k] = near_box of entry k, with σ² s2[k] = r2[k] / 9 (written), and the box
// [blo, bhi]; lo and hi: the least and greatest x of the entries kept, smax their largest
// σ² (all three unset when none is kept), reduced eight lanes at a time (the least and
// greatest of a set do not depend on the order they are taken in).
LEX3D_CLONES void box_keep(const float* lx, const float* ly, const float* lz, const float* r2, std::size_t n,
                           const float* blo, const float* bhi, float* s2, std::int32_t* keep, float& lo, float& hi,
                           float& smax) {
  float c[3], h[3];
  box_centre(blo, bhi, c, h);
  for (std::size_t k = 0; k < n; ++k) {
    s2[k] = r2[k] / 9.0F;
    keep[k] = near_box(lx[k], ly[k], lz[k], s2[k], c, h);
  }
  const float inf = std::numeric_limits<float>::infinity();
  V8f lo8 = splat8(inf), hi8 = splat8(-inf), s8 = hi8;
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    V8i kept;
    std::memcpy(&kept, keep + k, sizeof kept);
    kept = kept != 0;
    const V8f x = load8(lx + k), s = load8(s2 + k);
    lo8 = (kept & (x < lo8)) != 0 ? x : lo8;
    hi8 = (kept & (x > hi8)) != 0 ? x : hi8;
    s8 = (kept & (s > s8)) != 0 ? s : s8;
  }
  lo = inf;
  hi = smax = -inf;
  for (int l = 0; l < 8; ++l) {
    lo = std::min(lo, lo8[l]);
    hi = std::max(hi, hi8[l]);
    smax = std::max(smax, s8[l]);
  }
  for (; k < n; ++k)
    if (keep[k] != 0) {
      lo = std::min(lo, lx[k]);
      hi = std::max(hi, lx[k]);
      smax = std::max(smax, s2[k]);
    }
}

// How many of the n entries near_box finds near the box [blo, bhi].
LEX3D_CLONES std::size_t box_count(const float* lx, const float* ly, const float* lz, const float* s2, std::size_t n,
                                   const float* blo, const float* bhi) {
  float c[3], h[3];
  box_centre(blo, bhi, c, h);
  std::int32_t count = 0;
  for (std::size_t k = 0; k < n; ++k) count += near_box(lx[k], ly[k], lz[k], s2[k], c, h);
  return static_cast<std::size_t>(count);
}

// The entries of one feature that can be within their σ of a box (the union of the
// candidate words' bounding boxes), bucketed into slabs along x at least as wide as the
// largest σ among them (a counting sort), for the fit test of several words: an entry
// within its σ of a word point lies in the point's slab or one next to it, and those
// three slabs are one contiguous run. Entries left out are farther than σ from every
// point of those words.
// Makes v at least n long. The scratch arrays below are reused from one feature to the
// next with different lengths; resize() to a smaller then a larger length zero-fills the
// difference every time, where growing only does it once (every element read is written
// first).
template <class V>
inline void grow(V& v, std::size_t n) {
  if (v.size() < n) v.resize(n);
}

struct Slabs {
  std::vector<float> x, y, z, sig2;  // kept entries in slab order, padded to a multiple of 8 (the first `padded`)
  std::vector<std::uint32_t> start;  // slab b holds [start[b], start[b + 1])
  float x0 = 0.0F, inv = 0.0F;
  int count = 0;
  std::size_t size = 0;    // entries kept
  std::size_t padded = 0;  // size rounded up to a multiple of 8

  // r2: (3σ)² of each entry (σ² is taken as (3σ)² / 9).
  void build(const float* lx, const float* ly, const float* lz, const float* r2, std::size_t n, const float* blo,
             const float* bhi) {
    constexpr int kMaxSlabs = 64;
    grow(s2_, n);
    grow(keep_, n);
    float lo = 0.0F, hi = 0.0F, smax = 0.0F;
    box_keep(lx, ly, lz, r2, n, blo, bhi, s2_.data(), keep_.data(), lo, hi, smax);
    const float* const s2 = s2_.data();
    grow(kept_, n);
    std::size_t m = 0;
    for (std::size_t k = 0; k < n; ++k) {
      kept_[m] = static_cast<std::uint32_t>(k);
      m += static_cast<std::size_t>(keep_[k]);
    }
    size = m;
    const std::size_t npad = (size + 7) / 8 * 8;
    // Padded with entries nothing reaches (tests run in blocks of 8). The arrays only
    // grow: the first `size` are all written below, the padding here.
    padded = npad;
    grow(x, npad);
    grow(y, npad);
    grow(z, npad);
    grow(sig2, npad);
    for (std::size_t i = size; i < npad; ++i) {
      x[i] = y[i] = z[i] = 1e9F;
      sig2[i] = -1.0F;
    }
    if (size == 0) {
      count = 0;
      start.assign(1, 0);
      return;
    }
    // 0.1 % wider than the largest σ: floors of the scaled coordinates of an entry and a
    // word point within σ of it then differ by at most one despite rounding.
    float width = std::sqrt(smax) * 1.001F + 1e-6F;
    if ((hi - lo) / width > static_cast<float>(kMaxSlabs - 1)) width = (hi - lo) / static_cast<float>(kMaxSlabs - 1);
    x0 = lo;
    inv = 1.0F / width;
    count = std::min(kMaxSlabs, static_cast<int>((hi - lo) * inv) + 1);
    start.assign(static_cast<std::size_t>(count) + 1, 0);
    grow(slab_, size);
    for (std::size_t i = 0; i < size; ++i) {
      const int b = std::min(count - 1, std::max(0, static_cast<int>((lx[kept_[i]] - x0) * inv)));
      slab_[i] = static_cast<std::uint32_t>(b);
      ++start[static_cast<std::size_t>(b) + 1];
    }
    for (int b = 0; b < count; ++b) start[static_cast<std::size_t>(b) + 1] += start[static_cast<std::size_t>(b)];
    cursor_.assign(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < size; ++i) {
      const std::uint32_t k = kept_[i];
      const std::uint32_t at = cursor_[slab_[i]]++;
      x[at] = lx[k];
      y[at] = ly[k];
      z[at] = lz[k];
      sig2[at] = s2[k];
    }
  }
  // The run of entries that can be within σ of a point at x = px is [run_lo, run_hi):
  // the point's slab and the ones either side, clamped to the slabs there are (empty for
  // a point two slabs or more outside them; a NaN gives every entry). Both ends only grow
  // with px, so for x-sorted points a..d, [run_lo(a), run_hi(d)) holds all their runs.
  std::uint32_t run_lo(float px) const { return start[static_cast<std::size_t>(std::max(slab(px, -2) - 1, 0))]; }
  std::uint32_t run_hi(float px) const {
    return start[static_cast<std::size_t>(std::min(slab(px, count + 1) + 2, count))];
  }

 private:
  // floor((px - x0) / width), clamped to [-2, count + 1] (as far out as makes a
  // difference to the runs); `nan` for a NaN.
  int slab(float px, int nan) const {
    const float g = (px - x0) * inv;
    if (g > -2.0F && g < static_cast<float>(count) + 1.0F) return static_cast<int>(std::floor(g));
    if (g <= -2.0F) return -2;
    return g >= static_cast<float>(count) + 1.0F ? count + 1 : nan;
  }

  std::vector<std::uint32_t> kept_, slab_, cursor_;
  std::vector<std::int32_t> keep_;
  std::vector<float> s2_;
};

// Word choice by fit with slabs: the counts of fit_counts (entries with a word point
// within their σ, and the word points with no entry within σ). Each word point needs
// testing only against its three slabs, widened to whole blocks of 8 entries; the points
// go by in fours (the word's points sorted by x, so their runs mostly overlap), each four
// testing the run holding all their runs (Slabs::run_lo, run_hi): the entry loads, the
// update of the hits and the loop with its hard-to-predict exit are shared by the four.
// Every pair tested is compared as in fit_counts, and an entry outside a point's own run
// is farther than σ from it along x, so testing it as well changes no count. The np
// points are read padded to a multiple of 4 with far points (PackedWord::xp), which hit
// nothing and are not counted.
// Gives up (returns false, the counts unset) once `max_lonely` word points have no entry
// within σ (the count only grows, so that is the same as its final value reaching it).
LEX3D_CLONES bool fit_counts_slabs(const Slabs& s, const float* wx, const float* wy, const float* wz, std::size_t np,
                                   std::size_t max_lonely, std::int32_t* hit, std::size_t& explained,
                                   std::size_t& unsupported) {
  const std::size_t npad = s.padded;
  const float* lx = s.x.data();
  const float* ly = s.y.data();
  const float* lz = s.z.data();
  const float* sig2 = s.sig2.data();
  for (std::size_t k = 0; k < npad; ++k) hit[k] = 0;
  std::size_t lonely = 0;
  for (std::size_t p = 0; p < np; p += 4) {
    const std::size_t real = std::min<std::size_t>(4, np - p);  // the rest are padding
    const std::uint32_t lo = s.run_lo(wx[p]), hi = s.run_hi(wx[p + real - 1]);
    const V8f ax = splat8(wx[p]), ay = splat8(wy[p]), az = splat8(wz[p]);
    const V8f bx = splat8(wx[p + 1]), by = splat8(wy[p + 1]), bz = splat8(wz[p + 1]);
    const V8f cx = splat8(wx[p + 2]), cy = splat8(wy[p + 2]), cz = splat8(wz[p + 2]);
    const V8f dx = splat8(wx[p + 3]), dy = splat8(wy[p + 3]), dz = splat8(wz[p + 3]);
    V8i anya = {0, 0, 0, 0, 0, 0, 0, 0}, anyb = anya, anyc = anya, anyd = anya;
    for (std::size_t k = lo & ~7U; k < hi; k += 8) {
      const V8f ex = load8(lx + k), ey = load8(ly + k), ez = load8(lz + k), es = load8(sig2 + k);
      const V8f a0 = ax - ex, a1 = ay - ey, a2 = az - ez;
      const V8f b0 = bx - ex, b1 = by - ey, b2 = bz - ez;
      const V8f c0 = cx - ex, c1 = cy - ey, c2 = cz - ez;
      const V8f d0 = dx - ex, d1 = dy - ey, d2 = dz - ez;
      // The masks as they come (all ones or zero): hit[k] is nonzero when entry k is hit.
      const V8i ma = a0 * a0 + a1 * a1 + a2 * a2 <= es;
      const V8i mb = b0 * b0 + b1 * b1 + b2 * b2 <= es;
      const V8i mc = c0 * c0 + c1 * c1 + c2 * c2 <= es;
      const V8i md = d0 * d0 + d1 * d1 + d2 * d2 <= es;
      V8i h;
      std::memcpy(&h, hit + k, sizeof h);
      h |= (ma | mb) | (mc | md);
      std::memcpy(hit + k, &h, sizeof h);
      anya |= ma;
      anyb |= mb;
      anyc |= mc;
      anyd |= md;
    }
    lonely += (any8(anya) ? 0 : 1) + (any8(anyb) ? 0 : 1) + (any8(anyc) ? 0 : 1) + (any8(anyd) ? 0 : 1) - (4 - real);
    if (lonely >= max_lonely) return false;
  }
  std::size_t e = 0;
  for (std::size_t k = 0; k < s.size; ++k) e += hit[k] != 0 ? 1 : 0;
  explained = e;
  unsupported = lonely;
  return true;
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

// The n points pts[idx[k]] in a frame T (m: its 4x4 matrix, column-major), as frame_row
// computes them, eight at a time, into (x, y, z); with each point's reach2[idx[k]] into r2.
LEX3D_CLONES void points_in_frame(const float* m, const Eigen::Vector3f* pts, const std::uint32_t* idx,
                                  const float* reach2, std::size_t n, float* x, float* y, float* z, float* r2) {
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    V8f px, py, pz, pr;
    for (std::size_t l = 0; l < 8; ++l) {
      const std::uint32_t j = idx[k + l];
      px[l] = pts[j].x();
      py[l] = pts[j].y();
      pz[l] = pts[j].z();
      pr[l] = reach2[j];
    }
    float* const c[3] = {x, y, z};
    for (int r = 0; r < 3; ++r) {
      const V8f v = frame_row(m, r, px, py, pz);
      std::memcpy(c[r] + k, &v, sizeof v);
    }
    std::memcpy(r2 + k, &pr, sizeof pr);
  }
  for (; k < n; ++k) {
    const std::uint32_t j = idx[k];
    const float px = pts[j].x(), py = pts[j].y(), pz = pts[j].z();
    x[k] = frame_row(m, 0, px, py, pz);
    y[k] = frame_row(m, 1, px, py, pz);
    z[k] = frame_row(m, 2, px, py, pz);
    r2[k] = reach2[j];
  }
}

}  // namespace

ScanState::ScanState(const PreparedScan& scan, int threads) : scan_(scan) {
  const std::size_t n = scan.cloud.size();
  const std::size_t nf = scan.features.size();
  scale_.resize(n);
  log_floor_.resize(n);
  LargeVector<float> reach2(n);
  const double log_n = std::log(static_cast<double>(std::max<std::size_t>(n, 1)));
  for (std::size_t j = 0; j < n; ++j) {
    const double s = std::max(1e-4, static_cast<double>(scan.sigma[j]));
    scale_[j].a = static_cast<float>(1.0 / (2.0 * s * s));
    reach2[j] = static_cast<float>(9.0 * s * s);
    const double c = 2.0 * M_PI * s * s;
    scale_[j].norm = 1.0 / (c * std::sqrt(c));  // c^(-3/2)
    log_floor_[j] = -1.5 * std::log(c) - 4.5 - log_n;
  }
  S_.assign(n, 0.0);
  word_.assign(nf, -1);
  word_points_.assign(nf, 0);
  pose_.resize(nf);
  off_ = scan.nearby_offset.data();
  idx_ = scan.nearby_index.data();
  const std::size_t entries = off_[nf];
  lx_.resize(entries);
  ly_.resize(entries);
  lz_.resize(entries);
  reach2_e_.resize(entries);
  cache_.assign(entries, 0.0F);
  // delta_ stays empty until a change is first staged (all zeros then): the encoder never
  // stages one, so zeroing it here would only cost first touches of memory never read.
  const std::uint32_t* near = scan.nearby_index.data();
  parallel_for(nf, threads, [&](std::size_t f) {
    pose_[f] = scan.features.features[f].T_cloud_feature.cast<float>();
    const Eigen::Isometry3f T_feature_cloud = pose_[f].inverse();
    const std::size_t b = off_[f];
    points_in_frame(T_feature_cloud.matrix().data(), scan.cloud.points.data(), near + b, reach2.data(), off_[f + 1] - b,
                    lx_.data() + b, ly_.data() + b, lz_.data() + b, reach2_e_.data() + b);
  }, 64);
  recompute();
}

void ScanState::zeroed_delta() {
  if (delta_.size() != S_.size()) delta_.assign(S_.size(), 0.0);
}

double ScanState::log_or_minus_inf(double s) noexcept {
  return s > 0.0 ? std::log(s) : -std::numeric_limits<double>::infinity();
}

void ScanState::refresh_logs() {
  log_s_.resize(S_.size());
  for (std::size_t j = 0; j < S_.size(); ++j) log_s_[j] = log_or_minus_inf(S_[j]);
}

void ScanState::recompute() {
  // ln S is kept with S (the same values log() gives), so this needs no log() of its own.
  if (log_s_.size() != S_.size()) refresh_logs();
  const double lm = log_m(M_);
  log_l_ = 0.0;
  above_ = 0;
  for (std::size_t j = 0; j < S_.size(); ++j) {
    const double v = log_s_[j] - lm;
    if (v > log_floor_[j]) {
      log_l_ += v;
      ++above_;
    } else {
      log_l_ += log_floor_[j];
    }
  }
}

void ScanState::contribution_into(std::size_t f, const PackedWord& word, float* out) const {
  const std::size_t b = begin_of(f), e = end_of(f);
  if (word.size() == 0) {
    std::fill(out, out + (e - b), 0.0F);
    return;
  }
  const float lo[3] = {word.lo.x(), word.lo.y(), word.lo.z()};
  const float hi[3] = {word.hi.x(), word.hi.y(), word.hi.z()};
  gaussian_sums(lx_.data() + b, ly_.data() + b, lz_.data() + b, reach2_e_.data() + b, scale_.data(), e - b,
                word.xp.data(), word.yp.data(), word.zp.data(), word.size(), word.xp.size(), lo, hi, idx_ + b,
                out);
}

void ScanState::contribution(std::size_t f, const PackedWord& word, std::vector<float>& out) const {
  out.resize(end_of(f) - begin_of(f));
  contribution_into(f, word, out.data());
}

std::int64_t ScanState::stage(const std::vector<Change>& changes) {
  zeroed_delta();
  std::int64_t dm = 0;
  for (const auto& c : changes) {
    const std::size_t b = begin_of(c.feature), e = end_of(c.feature);
    const bool has_after = !c.contrib.empty();
    for (std::size_t k = b; k < e; ++k) {
      const double before = cache_[k];
      const double after = has_after ? c.contrib[k - b] : 0.0;
      if (before == 0.0 && after == 0.0) continue;
      const std::uint32_t j = idx_[k];
      if (delta_[j] == 0.0) touched_.push_back(j);
      delta_[j] += after - before;
      if (delta_[j] == 0.0) delta_[j] = 1e-300;  // keep it marked as touched
    }
    dm += static_cast<std::int64_t>(c.word_points) - static_cast<std::int64_t>(word_points_[c.feature]);
  }
  return dm;
}

std::int64_t ScanState::stage_removal(std::size_t f) {
  zeroed_delta();
  for (std::size_t k = begin_of(f); k < end_of(f); ++k) {
    const double before = cache_[k];
    if (before == 0.0) continue;
    const std::uint32_t j = idx_[k];
    if (delta_[j] == 0.0) touched_.push_back(j);
    delta_[j] += 0.0 - before;
    if (delta_[j] == 0.0) delta_[j] = 1e-300;  // keep it marked as touched
  }
  return -static_cast<std::int64_t>(word_points_[f]);
}

double ScanState::staged_delta(std::uint64_t m_new) {
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  double d = 0.0;
  std::size_t touched_above = 0;
  staged_log_.resize(touched_.size());
  for (std::size_t i = 0; i < touched_.size(); ++i) {
    const std::uint32_t j = touched_[i];
    const double ln_new = log_or_minus_inf(std::max(0.0, S_[j] + delta_[j]));
    staged_log_[i] = ln_new;
    d += term_of_log(j, ln_new, lm_new) - term_of_log(j, log_s_[j], lm_old);
    touched_above += above_of_log(j, log_s_[j], lm_old) ? 1 : 0;
  }
  // The untouched points above the background only see M change.
  return d - static_cast<double>(above_ - touched_above) * (lm_new - lm_old);
}

void ScanState::commit_staged(std::uint64_t m_new, double delta) {
  log_l_ += delta;
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  for (std::size_t i = 0; i < touched_.size(); ++i) {
    const std::uint32_t j = touched_[i];
    const bool was = above_of_log(j, log_s_[j], lm_old);
    S_[j] = std::max(0.0, S_[j] + delta_[j]);
    log_s_[j] = staged_log_[i];
    above_ = above_ + (above_of_log(j, log_s_[j], lm_new) ? 1 : 0) - (was ? 1 : 0);
  }
  unstage();
  M_ = m_new;
}

void ScanState::unstage() {
  for (const std::uint32_t j : touched_) delta_[j] = 0.0;
  touched_.clear();
}

double ScanState::delta_log_likelihood(const std::vector<Change>& changes) {
  const std::int64_t dm = stage(changes);
  const double d = staged_delta(static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) + dm));
  unstage();
  return d;
}

void ScanState::apply(const std::vector<Change>& changes) {
  const std::int64_t dm = stage(changes);
  const auto m_new = static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) + dm);
  commit_staged(m_new, staged_delta(m_new));
  for (const auto& c : changes) {
    word_[c.feature] = c.word;
    word_points_[c.feature] = c.word_points;
    const std::size_t b = begin_of(c.feature), e = end_of(c.feature);
    if (c.contrib.empty()) std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(b), cache_.begin() + static_cast<std::ptrdiff_t>(e), 0.0F);
    else std::copy(c.contrib.begin(), c.contrib.begin() + static_cast<std::ptrdiff_t>(e - b), cache_.begin() + static_cast<std::ptrdiff_t>(b));
  }
}

void ScanState::assign_words(const std::vector<std::int32_t>& words, const Alphabet& alphabet) {
  for (std::size_t f = 0; f < word_.size() && f < words.size(); ++f) {
    word_[f] = words[f];
    word_points_[f] = words[f] >= 0 ? static_cast<std::uint32_t>(alphabet.words[static_cast<std::size_t>(words[f])].points.size()) : 0U;
  }
  stale_ = true;
}

void ScanState::score_contributions(const Alphabet& alphabet, int threads) {
  const std::vector<PackedWord> packed = pack(alphabet);
  parallel_for(word_.size(), threads, [&](std::size_t f) {
    const std::size_t b = begin_of(f), e = end_of(f);
    if (word_[f] < 0) {
      std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(b), cache_.begin() + static_cast<std::ptrdiff_t>(e), 0.0F);
      return;
    }
    contribution_into(f, packed[static_cast<std::size_t>(word_[f])], cache_.data() + b);
  }, 16);
}

void ScanState::rescore(const Alphabet& alphabet, int threads) {
  if (!stale_) return;
  score_contributions(alphabet, threads);
  // Sums in feature order: the same S whatever the thread count.
  std::fill(S_.begin(), S_.end(), 0.0);
  M_ = 0;
  for (std::size_t f = 0; f < word_.size(); ++f) {
    if (word_[f] < 0) continue;
    M_ += word_points_[f];
    for (std::size_t k = begin_of(f); k < end_of(f); ++k) S_[idx_[k]] += static_cast<double>(cache_[k]);
  }
  stale_ = false;
  refresh_logs();
  recompute();
}

std::size_t ScanState::prune(const Alphabet& alphabet, int threads, bool keep_sole_cover) {
  // A stale state is scored as rescore() does, its S summed in the same order.
  const bool fresh = stale_;
  if (fresh) {
    score_contributions(alphabet, threads);
    std::fill(S_.begin(), S_.end(), 0.0);
    M_ = 0;
    for (std::size_t f = 0; f < word_.size(); ++f)
      if (word_[f] >= 0) M_ += word_points_[f];
  }
  std::vector<std::size_t> count(alphabet.size(), 0);
  for (const auto w : word_)
    if (w >= 0) ++count[static_cast<std::size_t>(w)];
  std::vector<std::uint32_t> order(alphabet.size());
  std::iota(order.begin(), order.end(), 0U);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return count[a] > count[b]; });
  // The features holding a word in the order they are tried: words in that order, the
  // features of each word in feature order (a counting sort).
  std::vector<std::size_t> start(alphabet.size());
  std::size_t placed = 0;
  for (const std::uint32_t w : order) {
    start[w] = placed;
    placed += count[w];
  }
  std::vector<std::uint32_t> seq(placed);
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (word_[f] >= 0) seq[start[static_cast<std::size_t>(word_[f])]++] = static_cast<std::uint32_t>(f);
  // With keep_sole_cover: which entries (instance, nearby scan point) have a word point
  // within the point's σ, and how many instances cover each scan point so.
  std::vector<std::uint8_t> covers;
  std::vector<std::uint32_t> cover_count;
  if (keep_sole_cover) {
    covers.assign(cache_.size(), 0);
    cover_count.assign(S_.size(), 0);
    const std::vector<PackedWord> packed = pack(alphabet);
    parallel_for(word_.size(), threads, [&](std::size_t f) {
      if (word_[f] < 0) return;
      const std::size_t b = begin_of(f), e = end_of(f);
      const PackedWord& w = packed[static_cast<std::size_t>(word_[f])];
      thread_local std::vector<std::int32_t> hits, sup;
      thread_local std::vector<float> sig2;
      hits.resize(e - b);
      sup.resize(w.size());
      sig2.resize(e - b);
      for (std::size_t k = b; k < e; ++k) sig2[k - b] = reach2_e_[k] / 9.0F;
      fit_counts(lx_.data() + b, ly_.data() + b, lz_.data() + b, sig2.data(), e - b, w.x.data(), w.y.data(),
                 w.z.data(), w.size(), hits.data(), sup.data());
      for (std::size_t k = b; k < e; ++k) covers[k] = hits[k - b] != 0 ? 1 : 0;
    }, 16);
    for (std::size_t f = 0; f < word_.size(); ++f)
      if (word_[f] >= 0)
        for (std::size_t k = begin_of(f); k < end_of(f); ++k) cover_count[idx_[k]] += covers[k];
  }
  // rescore's sum, in feature order (the entries of features without a word hold 0).
  const std::size_t nf = word_.size();
  if (fresh)
    for (std::size_t f = 0; f < nf; ++f)
      for (std::size_t k = begin_of(f); k < end_of(f); ++k) S_[idx_[k]] += static_cast<double>(cache_[k]);
  // Whether some instance names a point twice among the entries it contributes to
  // (cache_ not 0): every removal then goes through stage_removal and staged_delta
  // instead (the points of one neighbourhood are distinct in practice). The scan lists
  // them in ascending order, which rules that out with no look at the points; other
  // lists are checked point by point.
  bool ascending = true;
  for (std::size_t f = 0; f < nf; ++f)
    for (std::size_t k = begin_of(f) + 1; k < end_of(f); ++k) ascending &= idx_[k - 1] < idx_[k];
  bool repeats = false;
  if (!ascending) {
    std::vector<std::uint32_t> last(S_.size(), std::numeric_limits<std::uint32_t>::max());
    for (std::size_t f = 0; f < nf; ++f) {
      const auto ff = static_cast<std::uint32_t>(f);
      for (std::size_t k = begin_of(f); k < end_of(f); ++k) {
        const std::uint32_t j = idx_[k];
        const bool nz = cache_[k] != 0.0F;
        repeats |= nz && last[j] == ff;
        last[j] = nz ? ff : last[j];
      }
    }
  }
  if (fresh) {
    stale_ = false;
    refresh_logs();
    recompute();
  }
  // With keep_sole_cover: whether f must stay; otherwise its cover is taken away.
  const auto sole_cover = [&](std::size_t f) {
    if (!keep_sole_cover) return false;
    for (std::size_t k = begin_of(f); k < end_of(f); ++k)
      if (covers[k] != 0 && cover_count[idx_[k]] == 1) return true;
    for (std::size_t k = begin_of(f); k < end_of(f); ++k) cover_count[idx_[k]] -= covers[k];
    return false;
  };
  const auto drop = [&](std::size_t f) {
    word_[f] = -1;
    word_points_[f] = 0;
    std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(begin_of(f)), cache_.begin() + static_cast<std::ptrdiff_t>(end_of(f)), 0.0F);
  };
  // Each removal is scored once: a dropped instance is committed from the same figures
  // (what delta_log_likelihood then apply would compute).
  std::size_t dropped = 0;
  if (repeats) {
    for (const std::uint32_t f : seq) {
      const std::int64_t dm = stage_removal(f);
      const auto m_new = static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) + dm);
      const double d = staged_delta(m_new);
      if (d < 0.0 || sole_cover(f)) {
        unstage();
        continue;
      }
      commit_staged(m_new, d);
      drop(f);
      ++dropped;
    }
    recompute();
    return dropped;
  }
  // No instance names a point twice: a removal is scored from its entries alone, Δ_j
  // being minus the entry's value (staged_delta's sum, in the same order). The entries
  // not 0 of each instance are listed first (no branch on the value), in scratch that
  // stays in cache: lists of all instances at once would be fresh memory, whose first
  // touch costs more than the scoring.
  std::vector<std::uint32_t> nz_j;
  std::vector<float> nz_c;
  for (std::size_t t = 0; t < seq.size(); ++t) {
    // The entries of the instance after next start to load (each instance's are
    // contiguous, but the instances come in no useful order).
    if (t + 2 < seq.size())
      for (std::size_t k = begin_of(seq[t + 2]); k < end_of(seq[t + 2]); k += 16) {
        __builtin_prefetch(&cache_[k]);
        __builtin_prefetch(&idx_[k]);
      }
    const std::uint32_t f = seq[t];
    const std::size_t b = begin_of(f), e = end_of(f);
    nz_j.resize(e - b);
    nz_c.resize(e - b);
    std::size_t ne = 0;
    for (std::size_t k = b; k < e; ++k) {
      nz_j[ne] = idx_[k];
      nz_c[ne] = cache_[k];
      ne += cache_[k] != 0.0F ? 1 : 0;
    }
    const auto m_new = static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) -
                                                  static_cast<std::int64_t>(word_points_[f]));
    const double lm_old = log_m(M_);
    const double lm_new = log_m(m_new);
    double d = 0.0;
    std::size_t touched_above = 0;
    staged_log_.resize(ne);
    // A removal is kept out as soon as it is certain to lower ln L: no term still to
    // come adds more than gain = ln M - ln M' (S_j only falls; the background stays), nor
    // does any point above the background not yet seen, so d plus that many gains bounds
    // the final d (the margin covers rounding). Saves the log() of the remaining points.
    const double gain = lm_old - lm_new;
    bool lowers = false;
    for (std::size_t i = 0; i < ne; ++i) {
      const std::uint32_t j = nz_j[i];
      const double ln_new = log_or_minus_inf(std::max(0.0, S_[j] + -static_cast<double>(nz_c[i])));
      staged_log_[i] = ln_new;
      d += term_of_log(j, ln_new, lm_new) - term_of_log(j, log_s_[j], lm_old);
      touched_above += above_of_log(j, log_s_[j], lm_old) ? 1 : 0;
      if ((i & 7) == 7) {
        const double most = d + static_cast<double>(above_ - touched_above + (ne - 1 - i)) * gain;
        if (most < -1e-6 * (1.0 + std::fabs(d))) {
          lowers = true;
          break;
        }
      }
    }
    if (lowers) continue;
    d -= static_cast<double>(above_ - touched_above) * (lm_new - lm_old);
    if (d < 0.0 || sole_cover(f)) continue;
    log_l_ += d;
    for (std::size_t i = 0; i < ne; ++i) {
      const std::uint32_t j = nz_j[i];
      const bool was = above_of_log(j, log_s_[j], lm_old);
      S_[j] = std::max(0.0, S_[j] + -static_cast<double>(nz_c[i]));
      log_s_[j] = staged_log_[i];
      above_ = above_ + (above_of_log(j, log_s_[j], lm_new) ? 1 : 0) - (was ? 1 : 0);
    }
    M_ = m_new;
    drop(f);
    ++dropped;
  }
  recompute();
  return dropped;
}

namespace {

// The rotation R maximising tr(R H) (Kabsch: H = U S Vᵀ, R = V diag(1, 1, ±1) Uᵀ
// with det R = 1). The two leading right singular vectors come in closed form from the
// eigenvectors of HᵀH, the left ones as H v / |H v|; the third of each is the cross
// product of the other two, which makes both bases right-handed and R a rotation (the
// sign Kabsch puts in the last place). When H has rank below 2 (the pairs on one line),
// Eigen's JacobiSVD decides.
Eigen::Matrix3d kabsch_rotation(const Eigen::Matrix3d& H) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(H.transpose() * H);
  const Eigen::Vector3d v1 = es.eigenvectors().col(2);
  Eigen::Vector3d v2 = es.eigenvectors().col(1);
  v2 = (v2 - v2.dot(v1) * v1).normalized();
  const Eigen::Vector3d h1 = H * v1, h2 = H * v2;
  const double n1 = h1.norm();
  if (n1 > 0.0 && std::isfinite(n1)) {
    const Eigen::Vector3d u1 = h1 / n1;
    const Eigen::Vector3d w2 = h2 - u1.dot(h2) * u1;
    const double n2 = w2.norm();
    if (n2 > 1e-9 * n1) {
      const Eigen::Vector3d u2 = w2 / n2;
      const Eigen::Vector3d v3 = v1.cross(v2), u3 = u1.cross(u2);
      return v1 * u1.transpose() + v2 * u2.transpose() + v3 * u3.transpose();
    }
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d V = svd.matrixV();
  Eigen::Matrix3d R = V * svd.matrixU().transpose();
  if (R.determinant() < 0.0) {
    V.col(2) *= -1.0;
    R = V * svd.matrixU().transpose();
  }
  return R;
}

// One rigid correction D (q ≈ D p) from the np word points (mx, my, mz) to their nearest
// targets, in the instance's frame; identity when fewer than 3 pairs fall within reach.
// `match[i]` is the target (tx, ty, tz)[match[i]] of word point i or -1. The pairs are
// gathered first (no branch on the match), each point as one vector of four doubles
// (x, y, z, 0); the sums run in double, in word point order, each coordinate (and each
// entry of H) in its own lane, so they are the sums one coordinate at a time would give.
typedef double V4d __attribute__((vector_size(32)));
inline V4d load4d(const double* p) {
  V4d v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
LEX3D_CLONES Eigen::Isometry3f fit_pairs(const float* mx, const float* my, const float* mz, std::size_t np, const float* tx,
                            const float* ty, const float* tz, const std::int32_t* match) {
  thread_local std::vector<double> pairs_buf;
  grow(pairs_buf, 8 * np);
  double* const a = pairs_buf.data();
  double* const b = a + 4 * np;
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < np; ++i) {
    // matched: 1 when match[i] >= 0; t: the target, 0 when none (as bits, no branch).
    const auto mi = static_cast<std::uint32_t>(match[i]);
    const std::uint32_t matched = (~mi) >> 31;
    const std::size_t t = mi & (0U - matched);
    const V4d va = {static_cast<double>(mx[i]), static_cast<double>(my[i]), static_cast<double>(mz[i]), 0.0};
    const V4d vb = {static_cast<double>(tx[t]), static_cast<double>(ty[t]), static_cast<double>(tz[t]), 0.0};
    std::memcpy(a + 4 * pairs, &va, sizeof va);
    std::memcpy(b + 4 * pairs, &vb, sizeof vb);
    pairs += matched;
  }
  Eigen::Isometry3f D = Eigen::Isometry3f::Identity();
  if (pairs < 3) return D;
  V4d ca = {0.0, 0.0, 0.0, 0.0}, cb = ca;
  for (std::size_t i = 0; i < pairs; ++i) {
    ca += load4d(a + 4 * i);
    cb += load4d(b + 4 * i);
  }
  const auto n = static_cast<double>(pairs);
  const V4d nv = {n, n, n, n};
  ca /= nv;
  cb /= nv;
  V4d h0 = {0.0, 0.0, 0.0, 0.0}, h1 = h0, h2 = h0;  // the rows of H
  for (std::size_t i = 0; i < pairs; ++i) {
    const V4d p = load4d(a + 4 * i) - ca, q = load4d(b + 4 * i) - cb;
    h0 += V4d{p[0], p[0], p[0], p[0]} * q;
    h1 += V4d{p[1], p[1], p[1], p[1]} * q;
    h2 += V4d{p[2], p[2], p[2], p[2]} * q;
  }
  Eigen::Matrix3d H;
  H << h0[0], h0[1], h0[2], h1[0], h1[1], h1[2], h2[0], h2[1], h2[2];
  const Eigen::Vector3d centre_a(ca[0], ca[1], ca[2]), centre_b(cb[0], cb[1], cb[2]);
  const Eigen::Matrix3d R = kabsch_rotation(H);
  const Eigen::Vector3d t = centre_b - R * centre_a;
  if (!R.allFinite() || !t.allFinite()) return D;
  D.linear() = R.cast<float>();
  D.translation() = t.cast<float>();
  return D;
}

// Moves the n points (x, y, z) by D as Eigen's Isometry3f * Vector3f does (frame_row), eight
// at a time, and stores their bounding box in box (lo x, y, z, hi x, y, z).
LEX3D_CLONES void move_points_impl(const float* m, float* x, float* y, float* z, std::size_t n, float* box) {
  V8f lo[3] = {splat8(1e30F), splat8(1e30F), splat8(1e30F)};
  V8f hi[3] = {splat8(-1e30F), splat8(-1e30F), splat8(-1e30F)};
  float* const c[3] = {x, y, z};
  std::size_t p = 0;
  for (; p + 8 <= n; p += 8) {
    const V8f px = load8(x + p), py = load8(y + p), pz = load8(z + p);
    for (int r = 0; r < 3; ++r) {
      const V8f v = frame_row(m, r, px, py, pz);
      std::memcpy(c[r] + p, &v, sizeof v);
      lo[r] = v < lo[r] ? v : lo[r];
      hi[r] = hi[r] < v ? v : hi[r];
    }
  }
  for (int r = 0; r < 3; ++r) {
    box[r] = lo[r][0];
    box[3 + r] = hi[r][0];
    for (int l = 1; l < 8; ++l) {
      box[r] = std::min(box[r], lo[r][l]);
      box[3 + r] = std::max(box[3 + r], hi[r][l]);
    }
  }
  for (; p < n; ++p) {
    const float px = x[p], py = y[p], pz = z[p];
    for (int r = 0; r < 3; ++r) {
      const float v = frame_row(m, r, px, py, pz);
      c[r][p] = v;
      box[r] = std::min(box[r], v);
      box[3 + r] = std::max(box[3 + r], v);
    }
  }
}

void move_points(const Eigen::Isometry3f& D, float* x, float* y, float* z, std::size_t n, float* box) {
  move_points_impl(D.matrix().data(), x, y, z, n, box);  // column-major 4x4
}

}  // namespace

void ScanState::refine(const Alphabet& alphabet, int iterations, double max_distance, int threads) {
  if (iterations <= 0) return;
  const float reach2 = static_cast<float>(max_distance * max_distance);
  const std::vector<PackedWord> packed = pack(alphabet);
  std::vector<std::size_t> active;
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (word_[f] >= 0) active.push_back(f);
  std::vector<Eigen::Isometry3f> correction(active.size(), Eigen::Isometry3f::Identity());
  // The new pose of instance i, and its entries moved into that frame (while they are in
  // cache from the fit).
  const auto finish = [&](std::size_t i) {
    const std::size_t f = active[i];
    pose_[f] = pose_[f] * correction[i];
    // Keep the rotation exactly orthonormal: float products drift.
    pose_[f].linear() = Eigen::Quaternionf(pose_[f].linear()).normalized().toRotationMatrix();
    // The entries by the inverse correction, eight at a time (move_points computes each
    // as Eigen's Isometry3f * Vector3f does).
    const Eigen::Isometry3f inv = correction[i].inverse();
    float box[6];
    const std::size_t b = begin_of(f);
    move_points(inv, lx_.data() + b, ly_.data() + b, lz_.data() + b, end_of(f) - b, box);
  };
  // The ICP fit of instance i (correction[i]).
  const auto fit = [&](std::size_t i) {
    const std::size_t f = active[i];
    // ICP in the instance's frame: D moves the word onto the nearby scan points;
    // the new pose is pose · D.
    const Word& word = alphabet.words[static_cast<std::size_t>(word_[f])];
    const PackedWord& pw = packed[static_cast<std::size_t>(word_[f])];
    Eigen::Isometry3f& total = correction[i];
    const std::size_t np = word.points.size();
    if (np == 0) return;
    // Only scan points near the word's bounding box can pair up (twice the reach
    // leaves room for the word to move).
    const float margin = 2.0F * static_cast<float>(max_distance);
    // Of those, a round searches only the ones within reach of a box around the moved
    // word (the others cannot match: no squared distance to a word point is below the
    // one to a box holding it). The box is the moved word's bounding box grown by
    // `slack`, kept while it still holds the moved word.
    const float slack = 0.1F * static_cast<float>(max_distance);
    thread_local std::vector<float> fx, fy, fz, mx, my, mz, best, rbox;
    std::size_t nr8 = 0;
    thread_local std::vector<std::int32_t> match;
    const std::size_t b = begin_of(f), e = end_of(f);
    grow(fx, e - b + 8);
    grow(fy, e - b + 8);
    grow(fz, e - b + 8);
    std::size_t nf = 0;
    float slo[3] = {0.0F, 0.0F, 0.0F}, shi[3] = {-1.0F, -1.0F, -1.0F};  // empty: filled in the first round
    const std::size_t npad = pw.xp.size();
    mx.assign(pw.xp.begin(), pw.xp.end());
    my.assign(pw.yp.begin(), pw.yp.end());
    mz.assign(pw.zp.begin(), pw.zp.end());
    grow(best, npad);
    grow(match, npad);
    // The moved word's bounding box (lo x, y, z, hi x, y, z), kept by move_points.
    float box[6] = {pw.lo.x(), pw.lo.y(), pw.lo.z(), pw.hi.x(), pw.hi.y(), pw.hi.z()};
    for (int it = 0; it < iterations; ++it) {
      const float lo0 = box[0], lo1 = box[1], lo2 = box[2], hi0 = box[3], hi1 = box[4], hi2 = box[5];
      if (!(lo0 >= slo[0] && lo1 >= slo[1] && lo2 >= slo[2] && hi0 <= shi[0] && hi1 <= shi[1] && hi2 <= shi[2])) {
        slo[0] = lo0 - slack;
        slo[1] = lo1 - slack;
        slo[2] = lo2 - slack;
        shi[0] = hi0 + slack;
        shi[1] = hi1 + slack;
        shi[2] = hi2 + slack;
        const float wlo[3] = {pw.lo.x(), pw.lo.y(), pw.lo.z()};
        const float whi[3] = {pw.hi.x(), pw.hi.y(), pw.hi.z()};
        nf = select_targets(lx_.data() + b, ly_.data() + b, lz_.data() + b, e - b, wlo, whi, margin, slo, shi, reach2,
                            fx.data(), fy.data(), fz.data());
        // Padding to a multiple of 8: far points nothing takes (the word's padding sits at +1e9).
        for (std::size_t t = nf; t < (nf + 7) / 8 * 8; ++t) fx[t] = fy[t] = fz[t] = -1e9F;
        nr8 = run_boxes(fx.data(), fy.data(), fz.data(), nf, rbox);
      }
      nearest_targets(fx.data(), fy.data(), fz.data(), rbox.data(), nr8, mx.data(), my.data(), mz.data(), np, npad, reach2, best.data(),
                      match.data());
      const Eigen::Isometry3f D =
          fit_pairs(mx.data(), my.data(), mz.data(), np, fx.data(), fy.data(), fz.data(), match.data());
      move_points(D, mx.data(), my.data(), mz.data(), np, box);
      total = D * total;
      // Converged: under 0.1 mm and 0.1 mrad.
      if (D.translation().norm() < 1e-4F && Eigen::AngleAxisf(D.linear()).angle() < 1e-4F) break;
    }
  };
  parallel_for(active.size(), threads, [&](std::size_t i) {
    fit(i);
    finish(i);
  }, 8);
  stale_ = true;
}

namespace {

// descriptor_distances_sq of q to every word, eight words at a time: the descriptors
// are stored transposed (value i of words w..w+7 side by side, nw8 words a row, the extra
// ones zero), a lane per word. Each lane does what descriptor_distances_sq does for its
// word, in the same order (value i into running sum i % 8, the values past the last
// block of 8 after the blocks, the eight sums added pairwise), so the distances have
// the same bits; there is no horizontal sum and no chain of dependent adds to wait on.
LEX3D_CLONES void distances_to_words(const float* q, const float* rows_t, std::size_t nw8, int dim, float* out) {
  const int blocks = dim / 8;
  for (std::size_t w = 0; w < nw8; w += 8) {
    V8f acc[8];
    for (int l = 0; l < 8; ++l) acc[l] = splat8(0.0F);
    for (int k = 0; k < blocks; ++k)
      for (int l = 0; l < 8; ++l) {
        const int i = 8 * k + l;
        const V8f d = splat8(q[i]) - load8(rows_t + static_cast<std::size_t>(i) * nw8 + w);
        acc[l] += d * d;
      }
    for (int l = 0; l < 8; ++l) {  // fixed indices keep acc in registers
      const int i = 8 * blocks + l;
      if (i >= dim) break;
      const V8f d = splat8(q[i]) - load8(rows_t + static_cast<std::size_t>(i) * nw8 + w);
      acc[l] += d * d;
    }
    const V8f sum = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
    std::memcpy(out + w, &sum, sizeof sum);
  }
}

// Word choice by fit for one feature: among the kk words `near` (nearest descriptor
// first), the one that best fits the feature's n entries (lx, ly, lz; r2: (3σ)² of each),
// as ScanState::choose_by_fit describes. Compiled for AVX2 too, with the slab loops.
LEX3D_CLONES std::uint32_t best_fit(const std::pair<float, std::uint32_t>* near, std::size_t kk,
                                    const std::vector<PackedWord>& packed, const float* lx, const float* ly,
                                    const float* lz, const float* r2, std::size_t n) {
  thread_local std::vector<std::int32_t> hits;
  thread_local Slabs slabs;
  float lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = packed[near[0].second].lo[a];
    hi[a] = packed[near[0].second].hi[a];
    for (std::size_t c = 1; c < kk; ++c) {
      lo[a] = std::min(lo[a], packed[near[c].second].lo[a]);
      hi[a] = std::max(hi[a], packed[near[c].second].hi[a]);
    }
  }
  slabs.build(lx, ly, lz, r2, n, lo, hi);
  grow(hits, slabs.padded);
  if (slabs.size == 0) {  // nothing explained: the first word with the fewest points
    std::size_t pick = 0;
    for (std::size_t c = 1; c < kk; ++c)
      if (packed[near[c].second].size() < packed[near[pick].second].size()) pick = c;
    return near[pick].second;
  }
  // The word with the highest score (explained - unsupported), the first in the list
  // on ties. A word explains at most the entries near its bounding box (`most`), so
  // the words are tried by decreasing `most`, and one is passed over, or given up
  // once enough of its points are found unsupported, when it can no longer win.
  thread_local std::vector<std::pair<std::int64_t, std::uint32_t>> order;  // (-most, position)
  order.clear();
  for (std::size_t c = 0; c < kk; ++c) {
    const PackedWord& w = packed[near[c].second];
    const float wlo[3] = {w.lo.x(), w.lo.y(), w.lo.z()}, whi[3] = {w.hi.x(), w.hi.y(), w.hi.z()};
    const std::size_t most =
        box_count(slabs.x.data(), slabs.y.data(), slabs.z.data(), slabs.sig2.data(), slabs.padded, wlo, whi);
    order.emplace_back(-static_cast<std::int64_t>(most), static_cast<std::uint32_t>(c));
  }
  std::sort(order.begin(), order.end());
  std::int64_t best = 0;
  std::size_t best_c = kk;  // none yet
  for (const auto& [minus_most, c] : order) {
    const PackedWord& w = packed[near[c].second];
    // It must reach best, or best + 1 when it comes after the best word in the list.
    std::size_t max_lonely = std::numeric_limits<std::size_t>::max();
    if (best_c < kk) {
      const std::int64_t slack = -minus_most - best - (c > best_c ? 1 : 0);
      if (slack < 0) continue;
      max_lonely = static_cast<std::size_t>(slack) + 1;
    }
    std::size_t explained = 0, unsupported = 0;
    if (!fit_counts_slabs(slabs, w.xp.data(), w.yp.data(), w.zp.data(), w.size(), max_lonely, hits.data(), explained,
                          unsupported))
      continue;
    const std::int64_t score = static_cast<std::int64_t>(explained) - static_cast<std::int64_t>(unsupported);
    if (best_c == kk || score > best || (score == best && c < best_c)) {
      best = score;
      best_c = c;
    }
  }
  return near[best_c].second;
}

}  // namespace

std::size_t ScanState::choose_by_fit(const Alphabet& alphabet, int k, int threads, bool all_features) {
  if (alphabet.size() == 0) return 0;
  if (!all_features && (k <= 1 || alphabet.size() < 2)) return 0;
  const int dim = alphabet.descriptor_dim;
  const std::size_t nw = alphabet.size();
  // The words' points sorted by x (the fit counts do not depend on the order of the
  // points; fit_counts_slabs takes them four by four, and neighbours in x share most of
  // their slabs).
  std::vector<PackedWord> packed;
  packed.reserve(nw);
  for (const auto& w : alphabet.words) {
    Word sorted = w;
    std::stable_sort(sorted.points.begin(), sorted.points.end(),
                     [](const Eigen::Vector3f& a, const Eigen::Vector3f& b) { return a.x() < b.x(); });
    packed.emplace_back(sorted);
  }
  // The words' descriptors transposed (distances_to_words).
  const std::size_t nw8 = (nw + 7) / 8 * 8;
  std::vector<float> descriptors_t(nw8 * static_cast<std::size_t>(dim), 0.0F);
  for (std::size_t w = 0; w < nw; ++w)
    for (int i = 0; i < dim; ++i)
      descriptors_t[static_cast<std::size_t>(i) * nw8 + w] = alphabet.words[w].descriptor[static_cast<std::size_t>(i)];
  std::vector<std::size_t> active;
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (all_features || word_[f] >= 0) active.push_back(f);
  std::vector<std::int32_t> choice(active.size(), -1);
  const auto kk = std::min<std::size_t>(static_cast<std::size_t>(std::max(k, 1)), nw);
  parallel_for(active.size(), threads, [&](std::size_t i) {
    const std::size_t f = active[i];
    thread_local std::vector<float> dist;
    thread_local std::vector<std::pair<float, std::uint32_t>> near;
    // The kk nearest words by descriptor (ties: lower id), in order: words come by
    // increasing id, so one enters the list when strictly nearer than its last.
    dist.resize(nw8);
    distances_to_words(scan_.features.descriptor(f), descriptors_t.data(), nw8, dim, dist.data());
    near.clear();
    for (std::size_t w = 0; w < nw; ++w) {
      const float d = dist[w];
      if (near.size() == kk) {
        if (!(d < near.back().first)) continue;
        near.pop_back();
      }
      auto at = near.end();
      while (at != near.begin() && d < (at - 1)->first) --at;
      near.insert(at, {d, static_cast<std::uint32_t>(w)});
    }
    if (kk == 1) {
      choice[i] = static_cast<std::int32_t>(near[0].second);
      return;
    }
    const std::size_t b = begin_of(f), e = end_of(f);
    choice[i] = static_cast<std::int32_t>(best_fit(near.data(), kk, packed, lx_.data() + b, ly_.data() + b,
                                                   lz_.data() + b, reach2_e_.data() + b, e - b));
  }, 8);
  std::size_t changed = 0;
  for (std::size_t i = 0; i < active.size(); ++i) {
    const std::size_t f = active[i];
    if (choice[i] < 0 || choice[i] == word_[f]) continue;
    word_[f] = choice[i];
    word_points_[f] = static_cast<std::uint32_t>(alphabet.words[static_cast<std::size_t>(choice[i])].points.size());
    ++changed;
  }
  if (changed > 0) stale_ = true;
  return changed;
}

Model ScanState::model() const {
  Model m;
  // Sized first: growing the list copies it and touches fresh memory at each doubling.
  m.instances.reserve(static_cast<std::size_t>(
      std::count_if(word_.begin(), word_.end(), [](std::int32_t w) { return w >= 0; })));
  for (std::size_t f = 0; f < word_.size(); ++f) {
    if (word_[f] < 0) continue;
    Instance inst;
    inst.word = static_cast<std::uint32_t>(word_[f]);
    inst.T_cloud_word = pose_[f].cast<double>();
    // Orthonormal to double precision (the file format checks it to 1e-6): a feature frame
    // built in float from a short tangent vector, left as it is without ICP fitting
    // (refine_iterations 0), is off by up to ~1e-5.
    inst.T_cloud_word.linear() = Eigen::Quaterniond(inst.T_cloud_word.linear()).normalized().toRotationMatrix();
    inst.feature = static_cast<std::uint32_t>(f);
    m.instances.push_back(inst);
  }
  return m;
}

}  // namespace lex3d::detail
