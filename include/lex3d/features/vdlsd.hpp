#pragma once
/// \file
/// Variable-dimensional local shape descriptors (VD-LSD; Taati et al. 2007, as configured by
/// collier2012 §3.1): a joint histogram, over the points around a feature, of three positional
/// properties (the point's x, y, z in the feature's 6-DoF frame) and three dispersion
/// properties (the shape class of the point's own neighbourhood from the eigenvalues of its
/// covariance: linearity, planarity, scattering), each in `bins` bins, so bins^6 values
/// (collier2012: 2 bins, 64 values).

#include <cstddef>
#include <vector>

#include "lex3d/core/cloud.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Parameters of the VD-LSD.
struct VdlsdParams {
  /// Radius of the support sphere around a feature point, metres (the patch descriptor's
  /// half side, steder2010: 1.25); (0, 100].
  double support_radius = 1.25;
  /// Radius of the neighbourhood whose covariance gives a support point's shape, metres; it
  /// grows with the point's range to 2.5 beam spacings (`beam_spacing_rad`), as the patch
  /// descriptor's normal does, so that a far neighbourhood spans several beams; (0, 10].
  double local_radius = 0.2;
  /// Angular spacing of the sensor's beams, radians (the coarser of the two; a range image's
  /// measured spacing); 0 keeps `local_radius` at every range; [0, 0.2].
  double beam_spacing_rad = 0.0;
  /// Nearest points of a local neighbourhood used at most; [5, 4096].
  int local_points = 64;
  /// Bins along each of the six properties (collier2012: 2); [2, 3].
  int bins = 2;
  /// Support points of a feature used at most, evenly spaced in index order; [8, 65536].
  int max_support = 128;
  /// Fewest support points with a shape (a neighbourhood of 5 or more points that is not a
  /// single point) for a descriptor; a feature with fewer gets the empty descriptor (every
  /// value -1) and is counted in VdlsdResult::empty; [1, 65536].
  int min_support = 8;
  void validate() const;
};

/// Descriptors of the frames given to describe_vdlsd, in their order.
struct VdlsdResult {
  /// Row-major, frames x descriptor_dim, values in [-1, 1]: 2·sqrt(h) − 1 of the normalised
  /// histogram h (so that Euclidean distance is twice the Hellinger distance).
  std::vector<float> descriptors;
  int descriptor_dim = 0;
  /// Features whose support had fewer than min_support shaped points (empty descriptor).
  std::size_t empty = 0;
  /// Support points looked at (summed over features) and those without a shape (too few
  /// neighbours or all at one spot), which are left out of the histograms.
  std::size_t support_points = 0;
  std::size_t shapeless_points = 0;
  /// Distinct points whose neighbourhood covariance was computed.
  std::size_t shapes = 0;
};

/// bins^6.
[[nodiscard]] int vdlsd_dimension(int bins);

/// VD-LSDs of the points of `cloud` (cloud frame; ranges from cloud.T_cloud_sensor) around
/// each frame's origin, binned in that frame. Deterministic; does not depend on `threads`
/// ([1, 64]). Throws std::invalid_argument for bad parameters or a non-finite frame.
[[nodiscard]] VdlsdResult describe_vdlsd(const Cloud& cloud, const std::vector<Pose>& T_cloud_feature,
                                         const VdlsdParams& params, int threads = 1);

}  // namespace lex3d

#pragma GCC visibility pop
