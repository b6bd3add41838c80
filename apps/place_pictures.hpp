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
  /// score[q * scans + j]: the score of database scan j for query q (0 when not verified);
  /// NaN where j is not in q's database.
  std::vector<float> score;
  /// revisit[q * scans + j]: j is in q's database and within radius_m of it.
  std::vector<std::uint8_t> revisit;
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
