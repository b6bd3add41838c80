// Matching one scan against another: correspondences by descriptor (ratio test),
// candidate transforms from 1, 2 and 3 correspondences with the distance-consistency
// check (steder2010 §III-B), RANSAC inlier counting (collier2012 §3.2), Umeyama
// refinement, transforms from the dominant surfaces of the coarse images (normal-direction
// and wall-offset histograms), and steder2010's validation-point score (eq. 6-10).

#include <algorithm>
#include <cmath>
#include <limits>
#include <array>

#include <Eigen/Geometry>
#if defined(__SSE2__) && !defined(__FMA__)
#include <emmintrin.h>
#endif

#include "lex3d/place/place.hpp"
#include "lex3d/range/pixel_locator.hpp"

namespace lex3d {

namespace {

/// A transform hypothesis's pose and scores from one record to another (a PlaceMatch and
/// the PlaceAlternative kept of it, either way).
template <class From, class To>
void copy_hypothesis(const From& from, To& to) {
  to.T_match_query = from.T_match_query;
  to.score = from.score;
  to.score_query_in_match = from.score_query_in_match;
  to.score_match_in_query = from.score_match_in_query;
  to.inliers = from.inliers;
  to.descriptor_inliers = from.descriptor_inliers;
  to.rms_inlier_m = from.rms_inlier_m;
  to.sensor_distance_m = from.sensor_distance_m;
}

struct Correspondence {
  std::uint32_t q = 0;
  std::uint32_t m = 0;
  float distance = 0.0F;
};

std::vector<Correspondence> correspondences(const PlaceScan& query, const PlaceScan& cand, double ratio) {
  std::vector<Correspondence> out;
  const std::size_t nq = query.features.size();
  const std::size_t nm = cand.features.size();
  const int dim = query.descriptor_dim;
  if (nm < 2 || dim <= 0 || dim != cand.descriptor_dim) return out;
  const auto ud = static_cast<std::size_t>(dim);
  const float r2 = static_cast<float>(ratio * ratio);
  std::vector<float> dist(nm);
  for (std::size_t i = 0; i < nq; ++i) {
    const float* a = query.descriptors.data() + i * ud;
    // The same values as descriptor_distance_sq of each pair, a row at a time.
    descriptor_distances_sq(a, cand.descriptors.data(), nm, dim, dist.data());
    float b1 = std::numeric_limits<float>::infinity(), b2 = b1;
    std::size_t j1 = 0;
    for (std::size_t j = 0; j < nm; ++j) {
      const float d = dist[j];
      if (d < b1) {
        b2 = b1;
        b1 = d;
        j1 = j;
      } else if (d < b2) {
        b2 = d;
      }
    }
    if (b1 < r2 * b2)
      out.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j1), std::sqrt(b1)});
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const Correspondence& x, const Correspondence& y) { return x.distance < y.distance; });
  return out;
}

Pose frame(const PlaceFeature& f) {
  Pose T = Pose::Identity();
  T.linear() = f.rotation.cast<double>().toRotationMatrix();
  T.translation() = f.position.cast<double>();
  return T;
}

Pose umeyama_pose(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst) {
  Pose T = Pose::Identity();
  T.matrix() = Eigen::umeyama(src, dst, false);
  return T;
}

struct Hypothesis {
  Pose T = Pose::Identity();
  std::size_t inliers = 0;
  double residual = 0.0;  // sum of inlier distances
};

// SplitMix64: a small, portable, seeded generator (same sequence everywhere).
struct SplitMix {
  std::uint64_t s;
  std::uint64_t next() {
    std::uint64_t z = (s += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  std::size_t below(std::size_t n) { return static_cast<std::size_t>(next() % n); }
};

Eigen::Matrix3d gravity_rotation(const PlaceScan& s) {
  // Rotation of the cloud frame into a gravity-aligned frame (the world's rotation; only its
  // roll and pitch matter, an IMU would give them).
  return s.has_world_pose ? Eigen::Matrix3d(s.T_world_cloud.linear()) : Eigen::Matrix3d::Identity();
}

Pose rotation_pose(const Eigen::Matrix3d& R) {
  Pose T = Pose::Identity();
  T.linear() = R;
  return T;
}

// Hypotheses live in the gravity-aligned frames: G maps the query's aligned frame into the
// match's; T_match_query = Rm^T · G · Rq.
class Matcher {
 public:
  Matcher(const PlaceScan& q, const PlaceScan& m, std::vector<Correspondence> c, const PlaceParams& p)
      : q_(q), m_(m), c_(std::move(c)), p_(p), Rq_(gravity_rotation(q)), Rm_(gravity_rotation(m)) {
    gq_.reserve(q.features.size());
    gm_.reserve(m.features.size());
    for (const auto& f : q.features) gq_.push_back(Rq_ * f.position.cast<double>());
    for (const auto& f : m.features) gm_.push_back(Rm_ * f.position.cast<double>());
    for (const auto k : q.validation) gv_.push_back(gq_[k].cast<float>());
    for (const auto& v : gv_) {
      vx_.push_back(v.x());
      vy_.push_back(v.y());
      vz_.push_back(v.z());
    }
    mx_.reserve(gm_.size());
    for (std::size_t j = 0; j < gm_.size(); ++j) mx_.emplace_back(gm_[j].x(), static_cast<std::uint32_t>(j));
    std::sort(mx_.begin(), mx_.end());
    build_grid();
  }

  [[nodiscard]] Pose to_cloud(const Pose& G) const { return rotation_pose(Rm_.transpose()) * G * rotation_pose(Rq_); }
  [[nodiscard]] Pose to_gravity(const Pose& T) const { return rotation_pose(Rm_) * T * rotation_pose(Rq_.transpose()); }

  /// Query features that land in a cell within about inlier_distance of a match feature.
  /// With `from` and `inliers`: the count of the first `from` points is known to be `inliers`.
  [[nodiscard]] Hypothesis evaluate(const Pose& G, std::size_t limit = std::numeric_limits<std::size_t>::max(),
                                    std::size_t need = 0, std::size_t from = 0, std::size_t inliers = 0) const {
    Hypothesis h;
    h.T = G;
    h.inliers = inliers;
    const std::size_t n = std::min(limit, gv_.size());
    if (grid_.empty()) return h;
    // In grid units, single precision: the hot loop of hypothesis counting.
    const Eigen::Matrix3f R = G.linear().cast<float>() / static_cast<float>(cell_);
    const Eigen::Vector3f t = ((G.translation() - origin_) / cell_).cast<float>();
    // Stopping early (when even all remaining points could not reach `need`) is checked every
    // four points: a count that stops is below `need` either way, a count that does not is exact.
    std::size_t count = inliers;
    std::size_t k = from;
    auto add = [&](float ux, float uy, float uz, int x, int y, int z) {
      if (!(ux >= 0 && uy >= 0 && uz >= 0)) return;
      if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return;
      if (cell_set(cell_index(x, y, z))) ++count;
    };
#if defined(__SSE2__) && !defined(__FMA__)
    // Four points at a time, each coordinate summed as R * g + t sums it: r0·x + (r1·y + r2·z),
    // then + t (the same float operations in the same order, so the same cells; a build with
    // FMA may fuse the scalar expression, so it keeps the scalar loop).
    const auto row = [&](int i, __m128& a, __m128& b, __m128& c, __m128& d) {
      a = _mm_set1_ps(R(i, 0));
      b = _mm_set1_ps(R(i, 1));
      c = _mm_set1_ps(R(i, 2));
      d = _mm_set1_ps(t(i));
    };
    __m128 a0, a1, a2, at, b0, b1, b2, bt, c0, c1, c2, ct;
    row(0, a0, a1, a2, at);
    row(1, b0, b1, b2, bt);
    row(2, c0, c1, c2, ct);
    const __m128i dim_x = _mm_set1_epi32(dims_[0]), dim_y = _mm_set1_epi32(dims_[1]), dim_z = _mm_set1_epi32(dims_[2]);
    const auto in_grid = [](__m128i j, __m128i d) {
      return _mm_and_si128(_mm_cmpgt_epi32(j, _mm_set1_epi32(-1)), _mm_cmpgt_epi32(d, j));
    };
    for (; k + 4 <= n; k += 4) {
      if (count + (n - k) < need) break;
      const __m128 x = _mm_loadu_ps(vx_.data() + k), y = _mm_loadu_ps(vy_.data() + k), z = _mm_loadu_ps(vz_.data() + k);
      const __m128 ux = _mm_add_ps(_mm_add_ps(_mm_mul_ps(a0, x), _mm_add_ps(_mm_mul_ps(a1, y), _mm_mul_ps(a2, z))), at);
      const __m128 uy = _mm_add_ps(_mm_add_ps(_mm_mul_ps(b0, x), _mm_add_ps(_mm_mul_ps(b1, y), _mm_mul_ps(b2, z))), bt);
      const __m128 uz = _mm_add_ps(_mm_add_ps(_mm_mul_ps(c0, x), _mm_add_ps(_mm_mul_ps(c1, y), _mm_mul_ps(c2, z))), ct);
      const __m128 zero = _mm_setzero_ps();
      const int inside = _mm_movemask_ps(
          _mm_and_ps(_mm_and_ps(_mm_cmpge_ps(ux, zero), _mm_cmpge_ps(uy, zero)), _mm_cmpge_ps(uz, zero)));
      if (inside == 0) continue;
      // The cells, and whether they are in the grid (0 <= cell < dims; below 0 only for a
      // coordinate beyond the int range), as add() decides it.
      const __m128i jx = _mm_cvttps_epi32(ux), jy = _mm_cvttps_epi32(uy), jz = _mm_cvttps_epi32(uz);
      const __m128i ok = _mm_and_si128(_mm_and_si128(in_grid(jx, dim_x), in_grid(jy, dim_y)), in_grid(jz, dim_z));
      const int cells = inside & _mm_movemask_ps(_mm_castsi128_ps(ok));
      if (cells == 0) continue;
      alignas(16) std::int32_t ix[4], iy[4], iz[4];
      _mm_store_si128(reinterpret_cast<__m128i*>(ix), jx);
      _mm_store_si128(reinterpret_cast<__m128i*>(iy), jy);
      _mm_store_si128(reinterpret_cast<__m128i*>(iz), jz);
      for (int l = 0; l < 4; ++l)
        if (((cells >> l) & 1) != 0 && cell_set(cell_index(ix[l], iy[l], iz[l]))) ++count;
    }
#endif
    for (; k < n; ++k) {
      if (count + (n - k) < need) break;
      const Eigen::Vector3f u = R * gv_[k] + t;
      add(u.x(), u.y(), u.z(), static_cast<int>(u.x()), static_cast<int>(u.y()), static_cast<int>(u.z()));
    }
    h.inliers = count;
    return h;
  }

  /// Pairs (query feature, nearest match feature within inlier_distance) under G.
  [[nodiscard]] std::vector<std::pair<std::size_t, std::size_t>> pairs(const Pose& G) const {
    std::vector<std::pair<std::size_t, std::size_t>> out;
    const double d2max = p_.inlier_distance * p_.inlier_distance;
    // Only match features within the inlier distance in x can be within it in 3-D; the window
    // is a thousandth wider, far beyond the rounding of the distances.
    const double reach = p_.inlier_distance * 1.001;
    const std::size_t nm = gm_.size();
    for (std::size_t i = 0; i < gq_.size(); ++i) {
      const Eigen::Vector3d x = G * gq_[i];
      // The nearest within d2max; of equally near ones the highest index.
      double best = d2max;
      std::size_t bj = nm;
      auto it = std::lower_bound(mx_.begin(), mx_.end(), x.x() - reach,
                                 [](const std::pair<double, std::uint32_t>& e, double v) { return e.first < v; });
      for (; it != mx_.end() && it->first <= x.x() + reach; ++it) {
        const std::size_t j = it->second;
        const double d2 = (x - gm_[j]).squaredNorm();
        if (d2 < best || (d2 == best && (bj == nm || j > bj))) {
          best = d2;
          bj = j;
        }
      }
      if (bj < nm) out.emplace_back(i, bj);
    }
    return out;
  }

  [[nodiscard]] bool consistent(std::size_t a, std::size_t b) const {
    if (c_[a].q == c_[b].q || c_[a].m == c_[b].m) return false;
    const double dq = (gq_[c_[a].q] - gq_[c_[b].q]).norm();
    const double dm = (gm_[c_[a].m] - gm_[c_[b].m]).norm();
    return std::abs(dq - dm) <= p_.consistency_tolerance && dq > p_.consistency_tolerance;
  }

  [[nodiscard]] std::vector<Hypothesis> hypotheses() const {
    std::vector<Hypothesis> out;
    const std::size_t n = c_.size();
    const auto H = static_cast<std::size_t>(p_.hypotheses_per_size);
    SplitMix rng{p_.seed};
    // One correspondence: the two feature frames give the whole transform.
    for (std::size_t i = 0; i < std::min(n, H); ++i)
      out.push_back(evaluate(to_gravity(frame(m_.features[c_[i].m]) * frame(q_.features[c_[i].q]).inverse())));
    // Two correspondences: each point plus a virtual point 1 m along its normal.
    if (n >= 2) {
      std::size_t made = 0;
      for (std::size_t tries = 0; tries < 4 * H && made < H; ++tries) {
        const std::size_t a = rng.below(n), b = rng.below(n);
        if (a == b || !consistent(a, b)) continue;
        Eigen::Matrix3Xd s(3, 4), d(3, 4);
        Eigen::Index k = 0;
        for (const std::size_t i : {a, b}) {
          const auto& fq = q_.features[c_[i].q];
          const auto& fm = m_.features[c_[i].m];
          s.col(k) = gq_[c_[i].q];
          d.col(k) = gm_[c_[i].m];
          s.col(k + 1) = gq_[c_[i].q] + Rq_ * (fq.rotation * Eigen::Vector3f::UnitZ()).cast<double>();
          d.col(k + 1) = gm_[c_[i].m] + Rm_ * (fm.rotation * Eigen::Vector3f::UnitZ()).cast<double>();
          k += 2;
        }
        out.push_back(evaluate(umeyama_pose(s, d)));
        ++made;
      }
    }
    // Three correspondences, pairwise consistent and not collinear.
    if (n >= 3) {
      std::size_t made = 0;
      for (std::size_t tries = 0; tries < 4 * H && made < H; ++tries) {
        const std::size_t a = rng.below(n), b = rng.below(n), c = rng.below(n);
        if (a == b || a == c || b == c) continue;
        if (!consistent(a, b) || !consistent(a, c) || !consistent(b, c)) continue;
        const Eigen::Vector3d &A = gq_[c_[a].q], &B = gq_[c_[b].q], &C = gq_[c_[c].q];
        if ((B - A).cross(C - A).norm() < 0.1) continue;
        Eigen::Matrix3Xd s(3, 3), d(3, 3);
        s << A, B, C;
        d << gm_[c_[a].m], gm_[c_[b].m], gm_[c_[c].m];
        out.push_back(evaluate(umeyama_pose(s, d)));
        ++made;
      }
    }
    gravity_hypotheses(rng, out);
    return out;
  }

  /// Least squares on the inlier pairs, repeated (ICP on the features).
  [[nodiscard]] Hypothesis refine(const Pose& G0) const {
    Hypothesis h;
    h.T = G0;
    auto pr = pairs(G0);
    h.inliers = pr.size();
    for (int it = 0; it < p_.refine_iterations && pr.size() >= 3; ++it) {
      Eigen::Matrix3Xd s(3, static_cast<Eigen::Index>(pr.size())), d(3, static_cast<Eigen::Index>(pr.size()));
      for (std::size_t k = 0; k < pr.size(); ++k) {
        s.col(static_cast<Eigen::Index>(k)) = gq_[pr[k].first];
        d.col(static_cast<Eigen::Index>(k)) = gm_[pr[k].second];
      }
      const Pose G = umeyama_pose(s, d);
      auto pr2 = pairs(G);
      if (pr2.size() < pr.size()) break;
      h.T = G;
      h.inliers = pr2.size();
      const bool same = pr2 == pr;
      pr = std::move(pr2);
      if (same) break;
    }
    double sum = 0.0;
    for (const auto& [i, j] : pr) sum += (h.T * gq_[i] - gm_[j]).squaredNorm();
    h.residual = pr.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(pr.size()));
    return h;
  }

  /// Hypotheses from the scans' dominant surfaces, for revisits whose interest points barely
  /// repeat. In the upright frames only yaw and translation are unknown. The yaw comes from
  /// the circular correlation of the two scans' histograms of horizontal normal directions
  /// (walls, facades, poles); for each of its strongest peaks, the translation along a
  /// dominant horizontal direction u is the shift that best overlays the offsets u·p of the
  /// points whose normals face ±u (walls seen from the same side), the same along the second
  /// dominant direction, and the height from the points with vertical normals (ground,
  /// ceiling). Nothing here depends on the yaw of the upright frames.
  [[nodiscard]] std::vector<Pose> surface_hypotheses() const {
    std::vector<Pose> out;
    const auto nyaw = static_cast<std::size_t>(p_.surface_yaws);
    if (nyaw == 0 || q_.dense_points.empty() || m_.dense_points.empty()) return out;
    const Surfaces sq = surfaces(q_, Rq_), sm = surfaces(m_, Rm_);
    // Azimuth histograms of horizontal normals, kBins bins over 360 degrees.
    const std::vector<double> hq = azimuth_histogram(sq), hm = azimuth_histogram(sm);
    std::vector<double> corr(kBins, 0.0);  // corr[s]: query azimuth phi lands on phi + s bins
    for (int s = 0; s < kBins; ++s)
      for (int i = 0; i < kBins; ++i) corr[static_cast<std::size_t>(s)] += hq[static_cast<std::size_t>(i)] * hm[static_cast<std::size_t>((i + s) % kBins)];
    std::vector<std::pair<double, double>> yaws;  // (correlation, yaw in bins, interpolated)
    for (int s = 0; s < kBins; ++s) {
      const double c0 = corr[static_cast<std::size_t>((s + kBins - 1) % kBins)], c1 = corr[static_cast<std::size_t>(s)],
                   c2 = corr[static_cast<std::size_t>((s + 1) % kBins)];
      if (!(c1 > c0 && c1 >= c2)) continue;
      const double den = c0 - 2 * c1 + c2;
      yaws.emplace_back(c1, s + (den < 0 ? 0.5 * (c0 - c2) / den : 0.0));
    }
    std::stable_sort(yaws.begin(), yaws.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    // Peaks of less than a third of the best are dropped: on balm the four 90-degree-symmetric
    // peaks of a courtyard reach 0.5-1 of the best, the next ones 0.15 and less.
    while (!yaws.empty() && (yaws.size() > nyaw || yaws.back().first < yaws.front().first / 3.0)) yaws.pop_back();
    // Two dominant horizontal directions of the match scan (axial, at least 30 degrees apart:
    // the 2x2 system for the horizontal translation amplifies offset errors by at most 2).
    std::vector<double> axial(kBins / 2, 0.0);
    for (int b = 0; b < kBins; ++b) axial[static_cast<std::size_t>(b % (kBins / 2))] += hm[static_cast<std::size_t>(b)];
    const int a1 = static_cast<int>(std::max_element(axial.begin(), axial.end()) - axial.begin());
    int a2 = -1;
    for (int b = 0; b < kBins / 2; ++b) {
      const int d = std::abs(b - a1), dist = std::min(d, kBins / 2 - d);
      if (dist * 360 / kBins >= 30 && (a2 < 0 || axial[static_cast<std::size_t>(b)] > axial[static_cast<std::size_t>(a2)])) a2 = b;
    }
    if (a2 < 0 || axial[static_cast<std::size_t>(a2)] <= 0.0) return out;
    const auto direction = [](int b) {
      const double a = (b + 0.5) * 2.0 * M_PI / kBins;
      return Eigen::Vector3d(std::cos(a), std::sin(a), 0.0);
    };
    const Eigen::Vector3d u1 = direction(a1), u2 = direction(a2);
    // Sensor origins in the upright frames, for the max_distance bound on each offset.
    const Eigen::Vector3d oq = Rq_ * q_.coarse.T_cloud_sensor.translation();
    const Eigen::Vector3d om = Rm_ * m_.coarse.T_cloud_sensor.translation();
    // Walls facing a dominant direction within 15 degrees (cos 15° = 0.966); ground and
    // ceiling within 30 degrees of vertical (cos 30° = 0.866). The match's histograms and
    // the vertical shifts do not depend on the yaw.
    const float wall = 0.966F, level = 0.866F;
    const OffsetHistogram m1 = offset_histogram(sm, u1.cast<float>(), wall), m2 = offset_histogram(sm, u2.cast<float>(), wall);
    const std::vector<double> oz =
        best_shifts(offset_histogram(sq, Eigen::Vector3f::UnitZ(), level), offset_histogram(sm, Eigen::Vector3f::UnitZ(), level),
                    (om - oq).z(), 1);
    for (const auto& [c, ybins] : yaws) {
      const double yaw = ybins * 2.0 * M_PI / kBins;
      const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      const Eigen::Vector3d shift0 = om - R * oq;  // translation that puts the sensors together
      // Query offsets along u are offsets along R^T u in its own upright frame.
      const auto o1 = best_shifts(offset_histogram(sq, (R.transpose() * u1).cast<float>(), wall), m1, shift0.dot(u1), 2);
      const auto o2 = best_shifts(offset_histogram(sq, (R.transpose() * u2).cast<float>(), wall), m2, shift0.dot(u2), 2);
      if (o1.empty() || o2.empty()) continue;
      Eigen::Matrix2d A;
      A << u1.x(), u1.y(), u2.x(), u2.y();
      const double z = oz.empty() ? shift0.z() : oz.front();
      for (const double t1 : o1)
        for (const double t2 : o2) {
          const Eigen::Vector2d xy = A.inverse() * Eigen::Vector2d(t1, t2);
          Pose G = Pose::Identity();
          G.linear() = R;
          G.translation() = Eigen::Vector3d(xy.x(), xy.y(), z);
          out.push_back(G);
        }
    }
    return out;
  }

  /// Query features within inlier_distance of a match feature under G (no refinement).
  [[nodiscard]] Hypothesis unrefined(const Pose& G) const {
    Hypothesis h = evaluate(G);  // the grid count first: cheap, and most hypotheses end here
    if (h.inliers < static_cast<std::size_t>(p_.min_inliers)) return h;
    const auto pr = pairs(G);
    h.inliers = pr.size();
    double sum = 0.0;
    for (const auto& [i, j] : pr) sum += (G * gq_[i] - gm_[j]).squaredNorm();
    h.residual = pr.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(pr.size()));
    return h;
  }

  /// Ratio-test correspondences consistent with G.
  [[nodiscard]] std::size_t descriptor_inliers(const Pose& G) const {
    std::size_t k = 0;
    const double d2max = p_.inlier_distance * p_.inlier_distance;
    for (const auto& c : c_)
      if ((G * gq_[c.q] - gm_[c.m]).squaredNorm() <= d2max) ++k;
    return k;
  }

 private:

  // Surface hypotheses: 2-degree azimuth bins (the coarse image's pixels are 1.5 degrees
  // wide, so neighbouring-pixel normals scatter by a few degrees) and 0.1 m offset bins (what
  // dense alignment refines from easily; it converges from 0.3 m and 2 degrees).
  static constexpr int kBins = 180;
  static constexpr double kOffsetBin = 0.1;
  struct Surfaces {
    std::vector<Eigen::Vector3f> p, n;  // upright points and normals of the dense points
  };
  // About PlaceParams::dense_points of them, evenly strided (as dense alignment takes them):
  // the histograms need the dominant surfaces, not every point (on balm the four revisits
  // give the same hypotheses from all ~8000 points as from ~1600, at a fifth of the cost).
  [[nodiscard]] Surfaces surfaces(const PlaceScan& s, const Eigen::Matrix3d& R) const {
    Surfaces out;
    const Eigen::Matrix3f Rf = R.cast<float>();
    const std::size_t n = s.dense_points.size();
    const std::size_t stride = std::max<std::size_t>(1, n / static_cast<std::size_t>(p_.dense_points));
    out.p.reserve(n / stride + 1);
    out.n.reserve(n / stride + 1);
    for (std::size_t i = 0; i < n; i += stride) {
      out.p.push_back(Rf * s.dense_points[i]);
      out.n.push_back(Rf * s.dense_normals[i]);
    }
    return out;
  }
  // atan2 to about 0.22 degrees (atan z ≈ z·π/4 + 0.273·z·(1 - |z|) on |z| <= 1), which is
  // plenty for 2-degree bins and several times cheaper than std::atan2.
  static double fast_atan2(float y, float x) {
    const double ax = std::abs(static_cast<double>(x)), ay = std::abs(static_cast<double>(y));
    if (ax == 0.0 && ay == 0.0) return 0.0;
    const double z = std::min(ax, ay) / std::max(ax, ay);
    double a = z * (M_PI / 4 + 0.273 * (1.0 - z));
    if (ay > ax) a = M_PI / 2 - a;
    if (x < 0) a = M_PI - a;
    return y < 0 ? -a : a;
  }
  // Horizontal normals: within 30 degrees of horizontal (|n_z| < 0.5).
  static std::vector<double> azimuth_histogram(const Surfaces& s) {
    std::vector<double> h(kBins, 0.0);
    for (const auto& n : s.n) {
      if (std::abs(n.z()) >= 0.5F) continue;
      const double a = fast_atan2(n.y(), n.x());
      const int b = static_cast<int>(std::floor((a + M_PI) / (2.0 * M_PI) * kBins));
      h[static_cast<std::size_t>((b % kBins + kBins) % kBins)] += 1.0;
    }
    // Light circular smoothing [1 2 1] / 4: a wall's normals straddle bin borders.
    std::vector<double> sm(kBins);
    for (int b = 0; b < kBins; ++b)
      sm[static_cast<std::size_t>(b)] = 0.25 * h[static_cast<std::size_t>((b + kBins - 1) % kBins)] +
                                        0.5 * h[static_cast<std::size_t>(b)] + 0.25 * h[static_cast<std::size_t>((b + 1) % kBins)];
    return sm;
  }
  // Offsets u·p, in kOffsetBin bins, of the points whose normals face +u (side 0) or -u
  // (side 1) within the angle whose cosine is cmin: (bin, count) runs by bin, per side.
  struct OffsetHistogram {
    std::array<std::vector<std::pair<int, float>>, 2> side;
  };
  static OffsetHistogram offset_histogram(const Surfaces& s, const Eigen::Vector3f& u, float cmin) {
    OffsetHistogram h;
    std::array<std::vector<int>, 2> bins;
    int lo = std::numeric_limits<int>::max(), hi = std::numeric_limits<int>::min();
    for (std::size_t i = 0; i < s.p.size(); ++i) {
      const float c = s.n[i].dot(u);
      if (std::abs(c) < cmin) continue;
      const int b = static_cast<int>(std::floor(s.p[i].dot(u) / static_cast<float>(kOffsetBin)));
      bins[c > 0 ? 0 : 1].push_back(b);
      lo = std::min(lo, b);
      hi = std::max(hi, b);
    }
    if (lo > hi) return h;
    std::vector<float> count(static_cast<std::size_t>(hi - lo + 1));
    for (int side = 0; side < 2; ++side) {
      std::fill(count.begin(), count.end(), 0.0F);
      for (const int b : bins[static_cast<std::size_t>(side)]) count[static_cast<std::size_t>(b - lo)] += 1.0F;
      for (std::size_t k = 0; k < count.size(); ++k)
        if (count[k] > 0.0F) h.side[static_cast<std::size_t>(side)].emplace_back(lo + static_cast<int>(k), count[k]);
    }
    return h;
  }
  // The best `keep` shifts t (metres; match offset = query offset + t) overlaying the two
  // histograms, same sides only (a wall is seen from one side); of those, the ones within
  // max_distance of `centre` (the shift that puts the sensors together) when it is set.
  [[nodiscard]] std::vector<double> best_shifts(const OffsetHistogram& hq, const OffsetHistogram& hm, double centre,
                                                std::size_t keep) const {
    int s0 = std::numeric_limits<int>::max(), s1 = std::numeric_limits<int>::min();
    for (std::size_t side = 0; side < 2; ++side) {
      if (hq.side[side].empty() || hm.side[side].empty()) continue;
      s0 = std::min(s0, hm.side[side].front().first - hq.side[side].back().first);
      s1 = std::max(s1, hm.side[side].back().first - hq.side[side].front().first);
    }
    if (s0 > s1) return {};
    --s0;  // one spare bin each side for the smoothing and the peak test
    ++s1;
    std::vector<double> corr(static_cast<std::size_t>(s1 - s0 + 1), 0.0);
    for (std::size_t side = 0; side < 2; ++side)
      for (const auto& [bq, cq] : hq.side[side])
        for (const auto& [bm, cm] : hm.side[side]) corr[static_cast<std::size_t>(bm - bq - s0)] += static_cast<double>(cq * cm);
    // Smoothing [1 2 1] / 4: the offsets of a wall straddle bin borders.
    std::vector<double> c(corr.size(), 0.0);
    for (std::size_t i = 1; i + 1 < corr.size(); ++i) c[i] = 0.25 * corr[i - 1] + 0.5 * corr[i] + 0.25 * corr[i + 1];
    std::vector<std::pair<double, double>> peaks;  // (value, shift in metres)
    for (std::size_t i = 1; i + 1 < c.size(); ++i)
      if (c[i] > c[i - 1] && c[i] >= c[i + 1]) peaks.emplace_back(c[i], (static_cast<double>(i) + s0) * kOffsetBin);
    std::stable_sort(peaks.begin(), peaks.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    // The best `keep` overlays, of any distance; those beyond max_distance are dropped after
    // (not replaced by weaker overlays within it, which are what sliding ambiguities give).
    std::vector<double> out;
    for (std::size_t k = 0; k < std::min(keep, peaks.size()); ++k)
      if (p_.max_distance <= 0.0 || std::abs(peaks[k].second - centre) <= p_.max_distance) out.push_back(peaks[k].second);
    return out;
  }

  void gravity_hypotheses(SplitMix& rng, std::vector<Hypothesis>& out) const {
    const std::size_t nq = gq_.size(), nm = gm_.size();
    if (p_.gravity_pairs == 0 || nq < 2 || nm < 2) return;
    const double min_h = 1.0;
    const auto& table = m_.pairs;  // precomputed with the scan (same upright frame as gm_)
    const double tol = p_.consistency_tolerance;
    const auto want = static_cast<std::size_t>(p_.gravity_pairs);
    std::size_t made = 0;
    // Partial counts on the first validation points prune hopeless hypotheses early.
    const std::size_t probe = std::min<std::size_t>(24, q_.validation.size());
    std::size_t best_probe = 0;
    for (std::size_t tries = 0; tries < 10 * want && made < want; ++tries) {
      const std::size_t i = rng.below(nq), k = rng.below(nq);
      if (i == k) continue;
      const Eigen::Vector3d v = gq_[k] - gq_[i];
      const double h = std::hypot(v.x(), v.y());
      if (h < min_h) continue;
      ++made;
      const double aq = std::atan2(v.y(), v.x());
      const Eigen::Vector3d cq = 0.5 * (gq_[i] + gq_[k]);
      auto it = std::lower_bound(table.begin(), table.end(), h - tol,
                                 [](const PlaceScan::FeaturePair& e, double x) { return e.horizontal < x; });
      for (; it != table.end() && it->horizontal <= h + tol; ++it) {
        // The table holds each pair once (a < b): i, k map onto a, b and onto b, a.
        for (const int dir : {1, -1}) {
          if (std::abs(static_cast<float>(dir) * it->dz - v.z()) > tol) continue;
          const double yaw = it->angle + (dir > 0 ? 0.0 : M_PI) - aq;
          Pose G = Pose::Identity();
          G.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
          G.translation() = 0.5 * (gm_[it->a] + gm_[it->b]) - G.linear() * cq;
          const std::size_t need = std::max<std::size_t>(3, (best_probe + 1) / 2);
          const Hypothesis hp = evaluate(G, probe, need);
          if (hp.inliers < need) continue;
          best_probe = std::max(best_probe, hp.inliers);
          // A probe that reaches `need` counted all its points (it stops early only when it
          // cannot): the whole count goes on from there.
          out.push_back(evaluate(G, std::numeric_limits<std::size_t>::max(), 0, probe, hp.inliers));
        }
      }
    }
  }

  void build_grid() {
    cell_ = p_.inlier_distance / 2.0;
    if (gm_.empty()) return;
    Eigen::Vector3d lo = gm_.front(), hi = gm_.front();
    for (const auto& g : gm_) {
      lo = lo.cwiseMin(g);
      hi = hi.cwiseMax(g);
    }
    const double r = p_.inlier_distance;
    origin_ = lo - Eigen::Vector3d::Constant(r + cell_);
    for (int a = 0; a < 3; ++a)
      dims_[a] = static_cast<int>(std::ceil((hi[a] - lo[a] + 2 * (r + cell_)) / cell_)) + 1;
    if (static_cast<double>(dims_[0]) * dims_[1] * dims_[2] > 4e7) {  // absurd extent: no grid
      dims_ = {0, 0, 0};
      return;
    }
    // One bit a cell: an eighth of the memory to clear and to look up.
    grid_.assign((static_cast<std::size_t>(dims_[0]) * static_cast<std::size_t>(dims_[1]) * static_cast<std::size_t>(dims_[2]) + 63) / 64, 0);
    const int reach = static_cast<int>(std::ceil(r / cell_));
    for (const auto& g : gm_) {
      const Eigen::Vector3d u = (g - origin_) / cell_;
      const int cx = static_cast<int>(u.x()), cy = static_cast<int>(u.y()), cz = static_cast<int>(u.z());
      for (int z = cz - reach; z <= cz + reach; ++z)
        for (int y = cy - reach; y <= cy + reach; ++y)
          for (int x = cx - reach; x <= cx + reach; ++x) {
            if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) continue;
            const Eigen::Vector3d centre = origin_ + (Eigen::Vector3d(x, y, z) + Eigen::Vector3d::Constant(0.5)) * cell_;
            if ((centre - g).norm() <= r) {
              const std::size_t i = cell_index(x, y, z);
              grid_[i >> 6] |= std::uint64_t{1} << (i & 63);
            }
          }
    }
  }
  [[nodiscard]] std::size_t cell_index(int x, int y, int z) const {
    return (static_cast<std::size_t>(z) * static_cast<std::size_t>(dims_[1]) + static_cast<std::size_t>(y)) *
               static_cast<std::size_t>(dims_[0]) +
           static_cast<std::size_t>(x);
  }
  [[nodiscard]] bool cell_set(std::size_t i) const { return ((grid_[i >> 6] >> (i & 63)) & 1U) != 0; }
  [[nodiscard]] bool occupied(const Eigen::Vector3d& p) const {
    if (grid_.empty()) return false;
    const Eigen::Vector3d u = (p - origin_) / cell_;
    if (!(u.x() >= 0 && u.y() >= 0 && u.z() >= 0)) return false;
    const auto x = static_cast<int>(u.x()), y = static_cast<int>(u.y()), z = static_cast<int>(u.z());
    if (x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return false;
    return cell_set(cell_index(x, y, z));
  }

  const PlaceScan& q_;
  const PlaceScan& m_;
  std::vector<Correspondence> c_;
  const PlaceParams& p_;
  Eigen::Matrix3d Rq_, Rm_;
  std::vector<Eigen::Vector3d> gq_, gm_;
  std::vector<Eigen::Vector3f> gv_;  // upright query features in validation order
  std::vector<float> vx_, vy_, vz_;  // the same, a coordinate an array
  std::vector<std::pair<double, std::uint32_t>> mx_;  // (x of gm_[j], j), sorted
  double cell_ = 0.25;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  std::array<int, 3> dims_{0, 0, 0};
  std::vector<std::uint64_t> grid_;  // occupancy bits, cell_index order
};

bool close_poses(const Pose& a, const Pose& b) {
  const Pose d = a.inverse() * b;
  const double angle = Eigen::AngleAxisd(d.linear()).angle();
  return d.translation().norm() < 0.1 && angle < 1.0 * M_PI / 180.0;
}

Eigen::Vector3d up_in_cloud(const PlaceScan& s) {
  if (!s.has_world_pose) return Eigen::Vector3d::UnitZ();
  return s.T_world_cloud.linear().transpose() * Eigen::Vector3d::UnitZ();
}

// Looks up the dense point of `to` nearest to x (cloud frame of `to`) among the pixels
// around x's projection (±1 pixel); returns its index or -1.
// `locator` is built on to.coarse: the same pixel as its project(), found from tables.
int nearest_dense(const PlaceScan& to, const PixelLocator& locator, const Eigen::Isometry3f& T_sensor_cloud,
                  const Eigen::Vector3f& x, float max_d2) {
  const RangeImage& img = to.coarse;
  int xi = 0, yi = 0;
  float r = 0;
  if (!locator.locate(T_sensor_cloud * x, xi, yi, r)) return -1;
  int best = -1;
  float bd = max_d2;
  const int xs[3] = {img.wrap_x(xi - 1), img.wrap_x(xi), img.wrap_x(xi + 1)};
  for (int dy = -1; dy <= 1; ++dy) {
    const int yy = yi + dy;
    if (yy < 0 || yy >= img.height) continue;
    const std::int32_t* row = to.dense_index.data() + img.index(0, yy);
    for (const int xx : xs) {
      if (xx < 0) continue;
      const std::int32_t k = row[xx];
      if (k < 0) continue;
      const float d2 = (to.dense_points[static_cast<std::size_t>(k)] - x).squaredNorm();
      if (d2 < bd) {
        bd = d2;
        best = k;
      }
    }
  }
  return best;
}

Pose small_motion(const Eigen::Matrix<double, 6, 1>& xi) {
  Pose D = Pose::Identity();
  const Eigen::Vector3d w = xi.head<3>();
  const double a = w.norm();
  if (a > 0) D.linear() = Eigen::AngleAxisd(a, w / a).toRotationMatrix();
  D.translation() = xi.tail<3>();
  return D;
}

/// Records the sensor distance `m.T_match_query` implies and applies PlaceParams::max_distance.
void check_distance(const PlaceScan& query, const PlaceScan& candidate, PlaceMatch& m, const PlaceParams& params) {
  const Eigen::Vector3d o_q = m.T_match_query * query.coarse.T_cloud_sensor.translation();
  m.sensor_distance_m = (o_q - candidate.coarse.T_cloud_sensor.translation()).norm();
  if (params.max_distance > 0.0 && m.sensor_distance_m > params.max_distance) {
    m.rejected_distance = true;
    m.valid = false;
  }
}

}  // namespace

namespace {

// dense_align with the pixel locators of the two coarse images built by the caller.
DenseAlignment dense_align_located(const PlaceScan& query, const PlaceScan& match, const PixelLocator& locate_q,
                                   const PixelLocator& locate_m, const Pose& T0, const PlaceParams& params) {
  DenseAlignment out;
  out.T_match_query = T0;
  if (query.dense_points.empty() || match.dense_points.empty()) return out;
  const Eigen::Isometry3f Sm = match.coarse.T_cloud_sensor.inverse().cast<float>();
  const Eigen::Isometry3f Sq = query.coarse.T_cloud_sensor.inverse().cast<float>();
  const std::size_t nq = query.dense_points.size(), nm = match.dense_points.size();
  const std::size_t stride_q = std::max<std::size_t>(1, nq / static_cast<std::size_t>(params.dense_points));
  const std::size_t stride_m = std::max<std::size_t>(1, nm / static_cast<std::size_t>(params.dense_points));
  Pose T = T0;
  double gate = params.dense_gate_start;
  for (int it = 0; it < params.dense_iterations; ++it) {
    Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    const Eigen::Isometry3f Tf = T.cast<float>();
    const Eigen::Isometry3f Ti = T.inverse().cast<float>();
    const auto g2 = static_cast<float>(gate * gate);
    const double c = gate / 2.0;  // Cauchy weight scale
    std::size_t used = 0;
    double sq = 0;
    auto add = [&](const Eigen::Vector3d& Jr, const Eigen::Vector3d& Jt, double e) {
      Eigen::Matrix<double, 6, 1> J;
      J << Jr, Jt;
      const double w = 1.0 / (1.0 + (e * e) / (c * c));
      A.noalias() += w * J * J.transpose();
      b.noalias() += w * e * J;
      ++used;
      sq += e * e;
    };
    // Query points against the match's tangent planes.
    for (std::size_t i = 0; i < nq; i += stride_q) {
      const Eigen::Vector3f x = Tf * query.dense_points[i];
      const int k = nearest_dense(match, locate_m, Sm, x, g2);
      if (k < 0) continue;
      const Eigen::Vector3d n = match.dense_normals[static_cast<std::size_t>(k)].cast<double>();
      const Eigen::Vector3d xd = x.cast<double>();
      add(xd.cross(n), n, n.dot(xd - match.dense_points[static_cast<std::size_t>(k)].cast<double>()));
    }
    // Match points against the query's tangent planes (moved into the match frame).
    for (std::size_t i = 0; i < nm; i += stride_m) {
      const Eigen::Vector3f xm = match.dense_points[i];
      const int k = nearest_dense(query, locate_q, Sq, Ti * xm, g2);
      if (k < 0) continue;
      const auto ku = static_cast<std::size_t>(k);
      const Eigen::Vector3d n = T.linear() * query.dense_normals[ku].cast<double>();
      const Eigen::Vector3d y = T * query.dense_points[ku].cast<double>();
      const Eigen::Vector3d xd = xm.cast<double>();
      add(-xd.cross(n), -n, n.dot(xd - y));
    }
    out.used = used;
    out.rms_m = used ? std::sqrt(sq / static_cast<double>(used)) : 0.0;
    if (used < 12) return out;
    A += 1e-6 * Eigen::Matrix<double, 6, 6>::Identity();
    const Eigen::Matrix<double, 6, 1> xi = A.ldlt().solve(-b);
    if (!xi.allFinite()) return out;
    T = small_motion(xi) * T;
    T.linear() = Eigen::Quaterniond(T.linear()).normalized().toRotationMatrix();
    out.T_match_query = T;
    out.iterations = it + 1;
    gate = std::max(params.dense_gate_end, gate * 0.7);
    // Converged: a step under 0.01 degrees and 1 mm once the gate is at its end.
    if (xi.head<3>().norm() < 1.7e-4 && xi.tail<3>().norm() < 1e-3 && gate <= params.dense_gate_end) break;
  }
  return out;
}

// dense_consistency with the pixel locator of `to`'s coarse image.
DenseConsistency dense_consistency_located(const PlaceScan& from, const PlaceScan& to, const PixelLocator& locate_to,
                                           const Pose& T_to_from, const PlaceParams& params) {
  DenseConsistency out;
  const RangeImage& img = to.coarse;
  if (from.dense_points.empty() || img.empty()) return out;
  const Eigen::Isometry3f T = (img.T_cloud_sensor.inverse() * T_to_from).cast<float>();
  const auto dhat = static_cast<float>(params.max_range_difference);
  // The angle across which the other scan's return in a pixel may have been taken.
  const auto pixel = static_cast<float>(std::max(img.azimuth_resolution_rad, img.elevation_resolution_rad));
  const std::size_t n = from.dense_points.size();
  const std::size_t stride = std::max<std::size_t>(1, n / static_cast<std::size_t>(params.dense_points));
  for (std::size_t i = 0; i < n; i += stride) {
    ++out.points;
    const Eigen::Vector3f p = T * from.dense_points[i];
    int fxi = 0, yi = 0;
    float r = 0;
    if (!locate_to.locate(p, fxi, yi, r)) continue;
    const int xi = img.wrap_x(fxi);
    if (xi < 0 || yi < 0 || yi >= img.height) continue;
    const std::size_t ci = img.index(xi, yi);
    if (img.state[ci] == PixelState::kUnobserved) continue;
    bool support = false;
    for (int dy = -1; dy <= 1 && !support; ++dy) {
      const int yy = yi + dy;
      if (yy < 0 || yy >= img.height) continue;
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = img.wrap_x(xi + dx);
        if (xx < 0) continue;
        const std::size_t j = img.index(xx, yy);
        if (img.state[j] == PixelState::kValid && std::abs(img.range[j] - r) <= dhat) {
          support = true;
          break;
        }
      }
    }
    // A beam passed through the point's surface only when it went on beyond the range that
    // surface spans across one pixel: r · pixel · tan(incidence) more than at the point. On a
    // surface the other scan sees at a grazing angle (the ground a few metres off, a wall
    // along the beam) a return in the same pixel may be metres farther and still lie on it;
    // a surface it faces keeps the tolerance d̂.
    const float cos_incidence = std::max(1e-3F, std::abs((T.linear() * from.dense_normals[i]).dot(p)) / std::max(r, 1e-6F));
    const float spread = r * pixel * std::sqrt(std::max(0.0F, 1.0F - cos_incidence * cos_incidence)) / cos_incidence;
    if (support) {
      ++out.visible;
      ++out.support;
    } else if (img.state[ci] == PixelState::kMaxRange || img.range[ci] > r + dhat + spread) {
      ++out.visible;
      ++out.conflict;  // the other scan's beam passed through this point
    }
    // else: occluded in the other scan, no evidence
  }
  return out;
}

// validation_score with the pixel locator of `to`'s coarse image.
double validation_score_located(const PlaceScan& from, const PlaceScan& to, const PixelLocator& locate_to,
                                const Pose& T_to_from, const PlaceParams& params) {
  const RangeImage& img = to.coarse;
  const std::size_t n = std::min<std::size_t>(from.validation.size(), static_cast<std::size_t>(params.validation_points));
  if (n == 0 || img.empty()) return 0.0;
  const Eigen::Isometry3f T = (img.T_cloud_sensor.inverse() * T_to_from).cast<float>();
  const int e = params.error_radius_px;
  const auto dhat = static_cast<float>(params.max_range_difference);
  double sum = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Vector3f p = T * from.features[from.validation[k]].position;
    int xi = 0, yi = 0;
    float r = 0;
    if (!locate_to.locate(p, xi, yi, r)) continue;
    bool any = false;
    float best = -1.0F;
    for (int dy = -e; dy <= e; ++dy) {
      const int yy = yi + dy;
      if (yy < 0 || yy >= img.height) continue;
      for (int dx = -e; dx <= e; ++dx) {
        const int xx = img.wrap_x(xi + dx);
        if (xx < 0) continue;
        const std::size_t i = img.index(xx, yy);
        if (img.state[i] != PixelState::kValid) continue;
        any = true;
        const float diff = std::abs(img.range[i] - r);
        if (diff > dhat) continue;
        const float lambda = 0.75F + 0.25F / std::sqrt(static_cast<float>(dx * dx + dy * dy) + 1.0F);  // eq. 9
        best = std::max(best, (1.0F - diff / dhat) * lambda);                                           // eq. 8
      }
    }
    if (!any) continue;                                          // N empty: 0
    sum += best >= 0.0F ? static_cast<double>(best) : -params.penalty;  // N' empty: -p
  }
  return std::max(0.0, sum) / static_cast<double>(n);  // eq. 10
}

// Dense alignment of m from m.T_feature, its checks and scores.
void align_and_check(const PlaceScan& query, const PlaceScan& candidate, const PixelLocator& locate_q,
                     const PixelLocator& locate_m, PlaceMatch& m, const PlaceParams& params) {
  const DenseAlignment a = dense_align_located(query, candidate, locate_q, locate_m, m.T_feature, params);
  m.dense_rms_m = a.rms_m;
  m.dense_used = a.used;
  m.T_match_query = a.T_match_query;
  const Pose T_query_match = m.T_match_query.inverse();
  m.dense_q = dense_consistency_located(query, candidate, locate_m, m.T_match_query, params);
  m.dense_m = dense_consistency_located(candidate, query, locate_q, T_query_match, params);
  m.score_query_in_match = validation_score_located(query, candidate, locate_m, m.T_match_query, params);
  m.score_match_in_query = validation_score_located(candidate, query, locate_q, T_query_match, params);
  m.score = std::min(m.score_query_in_match, m.score_match_in_query);
  m.dense_refined = true;
  check_distance(query, candidate, m, params);
  if (params.max_conflict < 1.0 && std::max(m.dense_q.conflict_share(), m.dense_m.conflict_share()) > params.max_conflict) {
    m.rejected_conflict = true;
    m.valid = false;
  }
}

// refine_match with the pixel locators of the two coarse images: the best transform, then,
// while the aligned transform is rejected, the alternatives in turn. When every one is
// rejected, the best transform's result is kept (invalid, with its reasons).
void refine_match_located(const PlaceScan& query, const PlaceScan& candidate, const PixelLocator& locate_q,
                          const PixelLocator& locate_m, PlaceMatch& m, const PlaceParams& params) {
  if (!m.valid) return;
  const double min_score = params.dense_score_ratio * params.accept_score;
  if (m.score < min_score) {
    m.rejected_score = true;
    m.valid = false;
    return;
  }
  const PlaceMatch feature_stage = m;
  align_and_check(query, candidate, locate_q, locate_m, m, params);
  m.dense_tried = 1;
  const std::size_t tries = std::min<std::size_t>(feature_stage.alternatives.size(),
                                                  static_cast<std::size_t>(params.dense_hypotheses) - 1);
  for (std::size_t k = 0; k < tries && !m.valid; ++k) {
    const PlaceAlternative& a = feature_stage.alternatives[k];
    if (a.score < min_score) break;  // best first: the rest score lower still
    PlaceMatch c = feature_stage;
    copy_hypothesis(a, c);
    c.T_feature = a.T_match_query;
    align_and_check(query, candidate, locate_q, locate_m, c, params);
    c.dense_tried = k + 2;
    if (c.valid) m = std::move(c);
    else m.dense_tried = k + 2;
  }
}

}  // namespace

DenseAlignment dense_align(const PlaceScan& query, const PlaceScan& match, const Pose& T0, const PlaceParams& params) {
  const PixelLocator locate_q(query.coarse), locate_m(match.coarse);
  return dense_align_located(query, match, locate_q, locate_m, T0, params);
}

DenseConsistency dense_consistency(const PlaceScan& from, const PlaceScan& to, const Pose& T_to_from,
                                   const PlaceParams& params) {
  const PixelLocator locate_to(to.coarse);
  return dense_consistency_located(from, to, locate_to, T_to_from, params);
}

double validation_score(const PlaceScan& from, const PlaceScan& to, const Pose& T_to_from, const PlaceParams& params) {
  const PixelLocator locate_to(to.coarse);
  return validation_score_located(from, to, locate_to, T_to_from, params);
}

PlaceMatch match_scans(const PlaceScan& query, const PlaceScan& candidate, const PlaceParams& params) {
  params.validate();
  PlaceMatch out;
  auto corr = correspondences(query, candidate, params.ratio);
  out.correspondences = corr.size();
  const Matcher matcher(query, candidate, std::move(corr), params);
  std::vector<Hypothesis> hyps = matcher.hypotheses();
  out.hypotheses = hyps.size();
  std::stable_sort(hyps.begin(), hyps.end(),
                   [](const Hypothesis& a, const Hypothesis& b) { return a.inliers > b.inliers; });
  std::vector<Hypothesis> refined;
  for (const auto& h : hyps) {
    if (refined.size() >= static_cast<std::size_t>(params.scored_hypotheses)) break;
    if (h.inliers < static_cast<std::size_t>(params.min_inliers) / 2) break;
    const Hypothesis r = matcher.refine(h.T);
    bool dup = false;
    for (const auto& x : refined) dup = dup || close_poses(x.T, r.T);
    if (!dup) refined.push_back(r);
  }
  // Surface hypotheses are scored as they are: feature ICP would pull their 0.1 m / 2 degree
  // estimate towards interest points that repeat only to 0.3-0.5 m.
  const std::vector<Pose> surface = matcher.surface_hypotheses();
  out.hypotheses += surface.size();
  for (const Pose& G : surface) {
    const Hypothesis h = matcher.unrefined(G);
    bool dup = false;
    for (const auto& x : refined) dup = dup || close_poses(x.T, h.T);
    if (!dup) refined.push_back(h);
  }
  const PixelLocator locate_q(query.coarse), locate_m(candidate.coarse);
  bool first = true;
  std::vector<PlaceMatch> scored;  // valid transforms with a score above 0
  for (const auto& h : refined) {
    if (h.inliers < static_cast<std::size_t>(params.min_inliers)) continue;
    PlaceMatch m;
    m.T_match_query = matcher.to_cloud(h.T);
    m.inliers = h.inliers;
    m.descriptor_inliers = matcher.descriptor_inliers(h.T);
    m.correspondences = out.correspondences;
    m.hypotheses = out.hypotheses;
    m.rms_inlier_m = h.residual;
    m.valid = true;
    if (params.ground_vehicle) {
      const Eigen::Vector3d up_q = m.T_match_query.linear() * up_in_cloud(query);
      const Eigen::Vector3d up_m = up_in_cloud(candidate);
      const double tilt = std::acos(std::clamp(up_q.dot(up_m), -1.0, 1.0)) * 180.0 / M_PI;
      const double vertical = std::abs(m.T_match_query.translation().dot(up_m));
      if (tilt > params.max_tilt_deg || vertical > params.max_vertical_offset) {
        m.rejected_ground = true;
        m.valid = false;
      }
    }
    if (m.valid) check_distance(query, candidate, m, params);
    if (m.valid) {
      m.score_query_in_match = validation_score_located(query, candidate, locate_m, m.T_match_query, params);
      m.score_match_in_query = validation_score_located(candidate, query, locate_q, m.T_match_query.inverse(), params);
      m.score = std::min(m.score_query_in_match, m.score_match_in_query);
    }
    const bool better = first || (m.valid && (!out.valid || m.score > out.score ||
                                              (m.score == out.score && m.inliers > out.inliers)));
    if (better) out = m;
    first = false;
    if (m.valid && m.score > 0.0) scored.push_back(m);
  }
  // The runners-up, for dense alignment to fall back on: every other valid transform that
  // scored, best first (ties: more inliers, then the order they were made in).
  if (out.valid && params.dense_hypotheses > 1) {
    std::stable_sort(scored.begin(), scored.end(), [](const PlaceMatch& a, const PlaceMatch& b) {
      return a.score != b.score ? a.score > b.score : a.inliers > b.inliers;
    });
    for (const PlaceMatch& m : scored) {
      if (out.alternatives.size() + 1 >= static_cast<std::size_t>(params.dense_hypotheses)) break;
      if (m.T_match_query.matrix() == out.T_match_query.matrix()) continue;  // the best itself
      PlaceAlternative a;
      copy_hypothesis(m, a);
      out.alternatives.push_back(a);
    }
  }
  out.T_feature = out.T_match_query;
  if (out.valid && params.dense_iterations > 0) refine_match_located(query, candidate, locate_q, locate_m, out, params);
  return out;
}

void refine_match(const PlaceScan& query, const PlaceScan& candidate, PlaceMatch& m, const PlaceParams& params) {
  if (!m.valid) return;
  const PixelLocator locate_q(query.coarse), locate_m(candidate.coarse);
  refine_match_located(query, candidate, locate_q, locate_m, m, params);
}

}  // namespace lex3d
