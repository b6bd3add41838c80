#pragma once
/// \file
/// The recognition vocabulary of the place module (collier2012 §3): a vocabulary tree
/// (hierarchical k-means, Nistér and Stewénius 2006) learned from the place features'
/// descriptors of a training set, separate from the compression alphabet, plus the
/// statistics of a FAB-MAP-style appearance model over its leaf words: each leaf's share of
/// training scans and a Chow–Liu tree over leaf co-occurrence.
///
/// Word ids are tree node ids (the root, id 0, is never a word). A descriptor descends from
/// the root to the nearest child centre at each level; every node on its path is a word of
/// the scan (tf-idf over all levels degrades gracefully when a descriptor lands in a
/// neighbouring leaf). FAB-MAP uses the leaves only.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "lex3d/core/status.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

struct PlaceScan;

/// How a vocabulary is learned.
struct VocabularyParams {
  /// Leaf words at most (the tree's depth is the smallest with branching^depth >= words);
  /// [2, 2^20].
  int words = 4096;
  /// Children of an inner node (k of each k-means); [2, 256].
  int branching = 16;
  /// A node is split only when it holds at least this many training descriptors a child;
  /// [1, 1000]. Keeps leaves from being single descriptors.
  int min_descriptors_per_child = 2;
  /// k-means iterations of FLANN's hierarchical clustering at each node; [1, 100].
  int kmeans_iterations = 11;
  /// Seed of the k-means initialisation; the vocabulary is deterministic for a seed.
  std::uint64_t seed = 1;
  void validate() const;
};

/// Statistics of learning.
struct VocabularyStats {
  std::size_t training_scans = 0;
  std::size_t training_descriptors = 0;
  std::size_t leaves = 0;
  std::size_t nodes = 0;
  std::size_t chow_liu_edges = 0;  ///< leaf pairs linked by the Chow–Liu tree (a forest)
  double learn_ms = 0.0;
};

/// A vocabulary tree with its FAB-MAP statistics (formats/place_db.md §3.5, the VOCB chunk).
struct PlaceVocabulary {
  static constexpr std::uint32_t kNoParent = 0xFFFFFFFFu;
  int descriptor_dim = 0;
  int branching = 0;
  std::uint64_t seed = 0;
  std::uint32_t training_scans = 0;
  /// Children of each node; nodes are in breadth-first order, so node i's children are
  /// [first_child(i), first_child(i) + child_count[i]). 0 = a leaf (a FAB-MAP word).
  std::vector<std::uint32_t> child_count;
  /// Centre of every node but the root: (nodes - 1) x descriptor_dim, node i at row i - 1.
  std::vector<float> centres;
  /// Per node: share of training scans that hold the word, smoothed, in (0, 1).
  std::vector<float> p_word;
  /// Per node: its Chow–Liu parent (a leaf) or kNoParent (a root of the forest, and every
  /// inner node).
  std::vector<std::uint32_t> parent;
  /// Per node: p(word | parent word present), p(word | parent word absent), in (0, 1).
  std::vector<float> p_given_parent;
  std::vector<float> p_given_no_parent;
  /// Derived from child_count (finish()).
  std::vector<std::uint32_t> first_child;

  [[nodiscard]] std::size_t nodes() const noexcept { return child_count.size(); }
  [[nodiscard]] bool empty() const noexcept { return child_count.size() < 2; }
  [[nodiscard]] bool is_leaf(std::uint32_t node) const noexcept { return child_count[node] == 0; }
  [[nodiscard]] std::size_t leaves() const noexcept;
  /// Fills first_child; false when child_count is not a breadth-first tree of nodes() nodes.
  bool finish();
  /// Leaf of one descriptor (descriptor_dim values), and the nodes on its path (root excluded).
  void path(const float* descriptor, std::vector<std::uint32_t>& nodes_out) const;
  /// The bag of words of `n` descriptors: (node id, count) over every path node, sorted by id.
  [[nodiscard]] std::vector<std::pair<std::uint32_t, std::uint32_t>> words(const float* descriptors, std::size_t n) const;
  /// words() of a scan's (dequantised) descriptors; empty when the sizes differ.
  [[nodiscard]] std::vector<std::pair<std::uint32_t, std::uint32_t>> words(const PlaceScan& scan) const;
};

/// Learns a vocabulary from the descriptors of `scans` (each scan: features.size() x
/// descriptor_dim dequantised values): FLANN's hierarchical k-means at each node of the
/// tree, then the leaf statistics and the Chow–Liu tree (maximum spanning forest of the
/// mutual information of leaf pairs that co-occur in a training scan). Throws
/// std::invalid_argument for bad params, no descriptors, or scans of different sizes.
[[nodiscard]] PlaceVocabulary learn_vocabulary(const std::vector<const PlaceScan*>& scans, const VocabularyParams& params,
                                               VocabularyStats* stats = nullptr);

/// The VOCB payload of a vocabulary (formats/place_db.md §3.5).
[[nodiscard]] std::vector<std::uint8_t> encode_vocabulary(const PlaceVocabulary& v);
/// Parses a VOCB payload; every length is checked against the bytes left before allocating.
/// `base` is the payload's offset in its file (for the error's byte offset).
[[nodiscard]] StatusOr<PlaceVocabulary> decode_vocabulary(const std::uint8_t* p, std::size_t n, std::uint64_t base = 0);

}  // namespace lex3d

#pragma GCC visibility pop
