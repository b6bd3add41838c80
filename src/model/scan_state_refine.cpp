// ScanState::refine: the ICP pose fit of placed words to their scan points.

#include "model/scan_state.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include "lex3d/core/parallel.hpp"
#include "model/scan_state_simd.hpp"

namespace lex3d::detail {

namespace {

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

}  // namespace

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
  const std::vector<PackedWord> packed = pack_words(alphabet);
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


}  // namespace lex3d::detail
