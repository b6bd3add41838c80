// The alphabet a place database is built with when none is given: learned on a few scans
// spread evenly over the set.

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "lex3d/place/place.hpp"

namespace lex3d {

Alphabet learn_place_alphabet(std::size_t scan_count, const std::function<Cloud(std::size_t)>& scan,
                              std::size_t learn_scans, const LearnParams& params,
                              const std::function<void(const LearnProgress&)>& progress) {
  if (learn_scans == 0) throw std::invalid_argument("learn_place_alphabet: learn_scans must be at least 1, got 0");
  params.validate();
  const std::size_t k = std::min(scan_count, learn_scans);
  std::vector<Cloud> subset;
  subset.reserve(k);
  for (std::size_t i = 0; i < k; ++i) subset.push_back(scan(i * scan_count / k));
  return std::move(learn_alphabet(subset, params, progress).alphabet);
}

}  // namespace lex3d
