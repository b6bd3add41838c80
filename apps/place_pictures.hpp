// The pictures of `lex3d place eval`: the precision-recall curve and the score matrix.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "plot.hpp"

namespace lex3d::cli {

struct EvalPictures {
  std::string data_name;        ///< the folder of scans, for the titles
  std::string method;           ///< the recogniser, for the legend
  double radius_m = 0.0;        ///< a match is true within this planar distance
  double threshold = 0.0;       ///< the acceptance threshold on the score
  double min_gap_s = 0.0;       ///< a query's database holds the scans this much older
  std::size_t scans = 0;
  /// The score matrix in cells of k x k scans (k = 1 up to kMatrixCells scans), so that its
  /// memory stays bounded however long the sequence: set_scans first, then for every query
  /// its database scans (in_database) and their scores (set_score).
  static constexpr std::size_t kMatrixCells = 560;
  std::size_t k = 1, cells = 0;
  std::vector<float> score;           ///< cells x cells, the highest score; NaN: no database scan
  std::vector<std::uint8_t> revisit;  ///< cells x cells, 1: a database scan within radius_m
  void set_scans(std::size_t n);
  void in_database(std::size_t query, std::size_t scan, bool within_radius);
  void set_score(std::size_t query, std::size_t scan, double s);
  /// (query, database scan) of each accepted best match (score at the threshold or above).
  std::vector<std::array<std::size_t, 2>> accepted;
  std::vector<std::array<double, 3>> curve;  ///< threshold, precision, recall; thresholds falling
  double recall_at_precision_1 = 0.0;
  double precision = 0.0, recall = 0.0;      ///< at the threshold
  std::size_t positives = 0;                 ///< queries with a true revisit
};

/// Precision (y) against recall (x), the operating point at the threshold, a legend.
plot::Canvas draw_precision_recall(const EvalPictures& e);
/// Query scan (rows) against database scan (columns), coloured by score, revisits marked.
plot::Canvas draw_score_matrix(const EvalPictures& e);

}  // namespace lex3d::cli
