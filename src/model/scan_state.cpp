#include "model/scan_state.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <Eigen/SVD>

#include "lex3d/core/parallel.hpp"

namespace lex3d::detail {

ScanState::ScanState(const PreparedScan& scan) : scan_(scan) {
  const std::size_t n = scan.cloud.size();
  const std::size_t nf = scan.features.size();
  inv_two_sigma2_.resize(n);
  reach2_.resize(n);
  norm_.resize(n);
  log_floor_.resize(n);
  const double log_n = std::log(static_cast<double>(std::max<std::size_t>(n, 1)));
  for (std::size_t j = 0; j < n; ++j) {
    const double s = std::max(1e-4, static_cast<double>(scan.sigma[j]));
    inv_two_sigma2_[j] = static_cast<float>(1.0 / (2.0 * s * s));
    reach2_[j] = static_cast<float>(9.0 * s * s);
    norm_[j] = std::pow(2.0 * M_PI * s * s, -1.5);
    log_floor_[j] = std::log(norm_[j]) - 4.5 - log_n;
  }
  S_.assign(n, 0.0);
  delta_.assign(n, 0.0);
  word_.assign(nf, -1);
  word_points_.assign(nf, 0);
  cache_.resize(nf);
  local_.resize(nf);
  pose_.resize(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    pose_[f] = scan.features.features[f].T_cloud_feature.cast<float>();
    const Eigen::Isometry3f T_feature_cloud = pose_[f].inverse();
    local_[f].reserve(scan.nearby[f].size());
    for (const std::uint32_t j : scan.nearby[f]) local_[f].push_back(T_feature_cloud * scan.cloud.points[j]);
  }
  recompute();
}

void ScanState::recompute() {
  const double lm = log_m(M_);
  log_l_ = 0.0;
  above_ = 0;
  for (std::size_t j = 0; j < S_.size(); ++j) {
    log_l_ += log_term(j, S_[j], lm);
    above_ += above(j, S_[j], lm) ? 1 : 0;
  }
}

void ScanState::contribution(std::size_t f, const Word& word, std::vector<float>& out) const {
  const auto& nearby = scan_.nearby[f];
  const auto& local = local_[f];
  out.assign(nearby.size(), 0.0F);
  if (word.points.empty()) return;
  // The word's bounding box: a point farther than 3σ from it gets nothing.
  Eigen::Vector3f lo = word.points.front(), hi = lo;
  for (const auto& p : word.points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  for (std::size_t k = 0; k < nearby.size(); ++k) {
    const std::uint32_t j = nearby[k];
    const Eigen::Vector3f q = local[k];
    const float reach2 = reach2_[j];
    const Eigen::Vector3f outside = (lo - q).cwiseMax(q - hi).cwiseMax(0.0F);
    if (outside.squaredNorm() > reach2) continue;
    const float a = inv_two_sigma2_[j];
    float s = 0.0F;
    for (const auto& p : word.points) {
      const float d2 = (p - q).squaredNorm();
      if (d2 <= reach2) s += std::exp(-d2 * a);
    }
    out[k] = static_cast<float>(s * norm_[j]);
  }
}

std::int64_t ScanState::stage(const std::vector<Change>& changes) {
  std::int64_t dm = 0;
  for (const auto& c : changes) {
    const auto& nearby = scan_.nearby[c.feature];
    const auto& old = cache_[c.feature];
    for (std::size_t k = 0; k < nearby.size(); ++k) {
      const std::uint32_t j = nearby[k];
      const double before = k < old.size() ? old[k] : 0.0;
      const double after = k < c.contrib.size() ? c.contrib[k] : 0.0;
      if (before == 0.0 && after == 0.0) continue;
      if (delta_[j] == 0.0) touched_.push_back(j);
      delta_[j] += after - before;
      if (delta_[j] == 0.0) delta_[j] = 1e-300;  // keep it marked as touched
    }
    dm += static_cast<std::int64_t>(c.word_points) - static_cast<std::int64_t>(word_points_[c.feature]);
  }
  return dm;
}

double ScanState::staged_delta(std::uint64_t m_new) const {
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  double d = 0.0;
  std::size_t touched_above = 0;
  for (const std::uint32_t j : touched_) {
    const double s_new = std::max(0.0, S_[j] + delta_[j]);
    d += log_term(j, s_new, lm_new) - log_term(j, S_[j], lm_old);
    touched_above += above(j, S_[j], lm_old) ? 1 : 0;
  }
  // The untouched points above the background only see M change.
  return d - static_cast<double>(above_ - touched_above) * (lm_new - lm_old);
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

void ScanState::apply(std::vector<Change>& changes) {
  const std::int64_t dm = stage(changes);
  const auto m_new = static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) + dm);
  log_l_ += staged_delta(m_new);
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  for (const std::uint32_t j : touched_) {
    const bool was = above(j, S_[j], lm_old);
    S_[j] = std::max(0.0, S_[j] + delta_[j]);
    above_ = above_ + (above(j, S_[j], lm_new) ? 1 : 0) - (was ? 1 : 0);
  }
  unstage();
  for (auto& c : changes) {
    word_[c.feature] = c.word;
    word_points_[c.feature] = c.word_points;
    cache_[c.feature] = std::move(c.contrib);
  }
  M_ = m_new;
}

std::size_t ScanState::prune(const Alphabet& alphabet) {
  std::vector<std::size_t> count(alphabet.size(), 0);
  for (const auto w : word_)
    if (w >= 0) ++count[static_cast<std::size_t>(w)];
  std::vector<std::uint32_t> order(alphabet.size());
  std::iota(order.begin(), order.end(), 0U);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return count[a] > count[b]; });
  std::size_t dropped = 0;
  std::vector<Change> one(1);
  for (const std::uint32_t w : order) {
    for (std::size_t f = 0; f < word_.size(); ++f) {
      if (word_[f] != static_cast<std::int32_t>(w)) continue;
      one[0].feature = static_cast<std::uint32_t>(f);
      one[0].word = -1;
      one[0].word_points = 0;
      one[0].contrib.clear();
      if (delta_log_likelihood(one) >= 0.0) {
        apply(one);
        ++dropped;
      }
    }
  }
  recompute();
  return dropped;
}

namespace {

// One rigid correction D (q ≈ D p) from word points to their nearest scan points,
// in the instance's frame; identity when fewer than 3 pairs fall within reach.
Eigen::Isometry3f icp_step(const std::vector<Eigen::Vector3f>& word, const std::vector<Eigen::Vector3f>& scan,
                           float reach2) {
  Eigen::Vector3d ca = Eigen::Vector3d::Zero(), cb = Eigen::Vector3d::Zero();
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> pairs;
  pairs.reserve(word.size());
  for (const auto& p : word) {
    float best = reach2;
    const Eigen::Vector3f* match = nullptr;
    for (const auto& q : scan) {
      const float d = (q - p).squaredNorm();
      if (d < best) {
        best = d;
        match = &q;
      }
    }
    if (match == nullptr) continue;
    pairs.emplace_back(p.cast<double>(), match->cast<double>());
    ca += pairs.back().first;
    cb += pairs.back().second;
  }
  Eigen::Isometry3f D = Eigen::Isometry3f::Identity();
  if (pairs.size() < 3) return D;
  ca /= static_cast<double>(pairs.size());
  cb /= static_cast<double>(pairs.size());
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (const auto& [a, b] : pairs) H += (a - ca) * (b - cb).transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d V = svd.matrixV();
  Eigen::Matrix3d R = V * svd.matrixU().transpose();
  if (R.determinant() < 0.0) {
    V.col(2) *= -1.0;
    R = V * svd.matrixU().transpose();
  }
  const Eigen::Vector3d t = cb - R * ca;
  if (!R.allFinite() || !t.allFinite()) return D;
  D.linear() = R.cast<float>();
  D.translation() = t.cast<float>();
  return D;
}

}  // namespace

void ScanState::refine(const Alphabet& alphabet, int iterations, double max_distance, int threads) {
  if (iterations <= 0) return;
  const float reach2 = static_cast<float>(max_distance * max_distance);
  std::vector<std::size_t> active;
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (word_[f] >= 0) active.push_back(f);
  std::vector<Change> changes(active.size());
  std::vector<Eigen::Isometry3f> correction(active.size(), Eigen::Isometry3f::Identity());
  parallel_for(active.size(), threads, [&](std::size_t i) {
    const std::size_t f = active[i];
    // ICP in the instance's frame: D moves the word onto the nearby scan points;
    // the new pose is pose · D.
    Word moved = alphabet.words[static_cast<std::size_t>(word_[f])];
    Eigen::Isometry3f& total = correction[i];
    if (moved.points.empty()) return;
    // Only scan points near the word's bounding box can pair up (twice the reach
    // leaves room for the word to move).
    Eigen::Vector3f lo = moved.points.front(), hi = lo;
    for (const auto& p : moved.points) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const float margin = 2.0F * static_cast<float>(max_distance);
    std::vector<Eigen::Vector3f> targets;
    for (const auto& q : local_[f])
      if (((lo - q).cwiseMax(q - hi).array() <= margin).all()) targets.push_back(q);
    for (int it = 0; it < iterations; ++it) {
      const Eigen::Isometry3f D = icp_step(moved.points, targets, reach2);
      for (auto& p : moved.points) p = D * p;
      total = D * total;
      // Converged: under 0.1 mm and 0.1 mrad.
      const float angle = Eigen::AngleAxisf(D.linear()).angle();
      if (D.translation().norm() < 1e-4F && angle < 1e-4F) break;
    }
    Change& c = changes[i];
    c.feature = static_cast<std::uint32_t>(f);
    c.word = word_[f];
    c.word_points = word_points_[f];
    contribution(f, moved, c.contrib);  // the moved word against the unchanged frame
  }, 8);
  apply(changes);
  for (std::size_t i = 0; i < active.size(); ++i) {
    const std::size_t f = active[i];
    pose_[f] = pose_[f] * correction[i];
    // Keep the rotation exactly orthonormal: float products drift.
    pose_[f].linear() = Eigen::Quaternionf(pose_[f].linear()).normalized().toRotationMatrix();
    const Eigen::Isometry3f inv = correction[i].inverse();
    for (auto& q : local_[f]) q = inv * q;
  }
  recompute();
}

std::size_t ScanState::choose_by_fit(const Alphabet& alphabet, int k, int threads) {
  if (k <= 1 || alphabet.size() < 2) return 0;
  const int dim = alphabet.descriptor_dim;
  std::vector<std::size_t> active;
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (word_[f] >= 0) active.push_back(f);
  std::vector<std::int32_t> choice(active.size(), -1);
  parallel_for(active.size(), threads, [&](std::size_t i) {
    const std::size_t f = active[i];
    // The k nearest words by descriptor (ties: lower id).
    std::vector<std::pair<float, std::uint32_t>> near;
    for (std::size_t w = 0; w < alphabet.size(); ++w)
      near.emplace_back(descriptor_distance_sq(scan_.features.descriptor(f), alphabet.words[w].descriptor.data(), dim),
                        static_cast<std::uint32_t>(w));
    const auto kk = std::min<std::size_t>(static_cast<std::size_t>(k), near.size());
    std::partial_sort(near.begin(), near.begin() + static_cast<std::ptrdiff_t>(kk), near.end());
    const auto& nearby = scan_.nearby[f];
    const auto& local = local_[f];
    double best = -1e300;
    for (std::size_t c = 0; c < kk; ++c) {
      const Word& w = alphabet.words[near[c].second];
      std::vector<char> supported(w.points.size(), 0);
      std::size_t explained = 0;
      for (std::size_t n = 0; n < nearby.size(); ++n) {
        const float r2 = reach2_[nearby[n]] / 9.0F;  // σ²
        bool hit = false;
        for (std::size_t p = 0; p < w.points.size(); ++p)
          if ((w.points[p] - local[n]).squaredNorm() <= r2) {
            hit = true;
            supported[p] = 1;
          }
        explained += hit ? 1 : 0;
      }
      std::size_t unsupported = 0;
      for (const char sp : supported) unsupported += sp ? 0 : 1;
      const double score = static_cast<double>(explained) - static_cast<double>(unsupported);
      if (score > best) {
        best = score;
        choice[i] = static_cast<std::int32_t>(near[c].second);
      }
    }
  }, 8);
  std::vector<Change> changes;
  for (std::size_t i = 0; i < active.size(); ++i) {
    const std::size_t f = active[i];
    if (choice[i] < 0 || choice[i] == word_[f]) continue;
    Change c;
    c.feature = static_cast<std::uint32_t>(f);
    c.word = choice[i];
    c.word_points = static_cast<std::uint32_t>(alphabet.words[static_cast<std::size_t>(choice[i])].points.size());
    changes.push_back(std::move(c));
  }
  parallel_for(changes.size(), threads, [&](std::size_t i) {
    contribution(changes[i].feature, alphabet.words[static_cast<std::size_t>(changes[i].word)], changes[i].contrib);
  }, 8);
  apply(changes);
  recompute();
  return changes.size();
}

Model ScanState::model() const {
  Model m;
  for (std::size_t f = 0; f < word_.size(); ++f) {
    if (word_[f] < 0) continue;
    Instance inst;
    inst.word = static_cast<std::uint32_t>(word_[f]);
    inst.T_cloud_word = pose_[f].cast<double>();
    inst.feature = static_cast<std::uint32_t>(f);
    m.instances.push_back(inst);
  }
  return m;
}

}  // namespace lex3d::detail
