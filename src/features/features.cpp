#include <stdexcept>

#include "lex3d/core/timer.hpp"
#include "lex3d/features/features.hpp"

namespace lex3d {

void FeatureParams::validate() const {
  range.validate();
  interest.validate();
  coverage.validate();
  descriptor.validate();
  if (threads < 1 || threads > 64) throw std::invalid_argument("FeatureParams::threads must be in [1, 64]");
}

FeatureResult extract_features(const Cloud& cloud, const FeatureParams& params) {
  params.validate();
  FeatureResult res;
  Stopwatch sw;
  res.image = make_range_image(cloud, params.range);
  res.timings.range_image_ms = sw.lap_ms();
  std::vector<Keypoint> keypoints = detect_interest_points(res.image, params.interest, &res.interest);
  res.timings.interest_ms = sw.lap_ms();
  const std::vector<Keypoint> extra = coverage_points(cloud, res.image, keypoints, params.coverage);
  keypoints.insert(keypoints.end(), extra.begin(), extra.end());
  res.timings.coverage_ms = sw.lap_ms();
  res.features = describe(res.image, keypoints, params.descriptor, params.threads);
  res.timings.descriptor_ms = sw.lap_ms();
  return res;
}

}  // namespace lex3d
