#pragma once
/// \file
/// lex3d in one call: compress a point cloud into a model file in memory, decompress one,
/// learn an alphabet for a set of scans. The `lex3d` command's `compress`, `decompress`
/// and `learn` go through the same functions, so the bytes are the same for the same
/// settings. Link `lex3d::lex3d` (find_package(lex3d)); PCL users convert their clouds with
/// lex3d/core/pcl_conversions.hpp.
///
///     #include <lex3d/lex3d.hpp>
///     lex3d::Cloud cloud;                        // points in metres, sensor frame
///     cloud.points = {{1.f, 2.f, 0.5f}, ...};
///     lex3d::CompressOptions options;
///     options.max_error = 0.014;                 // every point within 14 mm, both ways
///     auto file = lex3d::compress(cloud, options);
///     if (!file.ok()) { /* file.status().to_string() */ }
///     auto back = lex3d::decompress(file.value().bytes);
///
/// Errors (see lex3d/core/status.hpp): invalid options, and a cloud with a non-finite
/// point or with per-point arrays of the wrong length, throw std::invalid_argument naming
/// what is wrong; data that cannot be decoded (a corrupt file, an alphabet that does not
/// belong) comes back as a non-ok Status with one line of explanation.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "lex3d/api/coding.hpp"
#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/model/model.hpp"
#include "lex3d/version.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// The library's version ("major.minor.patch"), as built; compare with
/// LEX3D_VERSION_STRING from lex3d/version.hpp to detect a header/library mismatch.
[[nodiscard]] const char* version() noexcept;

/// Settings of `compress` (those of `lex3d compress`): how the file is coded
/// (CodingOptions: max_error, target_bpp, words, layer_coding, quantization, threads),
/// plus how the alphabet is learned or which one is reused.
struct CompressOptions : CodingOptions {
  /// Word radius, feature and model settings of learning and modelling
  /// (ModelParams; its `threads` is replaced by CodingOptions::threads).
  ModelParams model;
  /// Candidate words drawn at most when learning; [1, 1e6] (`--iterations`).
  int max_iterations = LearnParams{}.max_iterations;
  /// Seed of the candidate order when learning (`--seed`).
  std::uint64_t seed = LearnParams{}.seed;
  /// An alphabet file to reuse (`--alphabet`): nothing is learned and the model file
  /// references it by content hash, so decompress needs it too. Empty (the default): an
  /// alphabet is learned on the scan and embedded (when words are used).
  std::vector<std::uint8_t> alphabet;
  /// Throws std::invalid_argument naming the field and its allowed range.
  void validate() const;
};

/// A compressed scan and how it was coded.
struct CompressResult {
  std::vector<std::uint8_t> bytes;       ///< the model file (formats/model.md)
  std::uint64_t input_points = 0;        ///< points of the input cloud
  std::size_t features = 0;              ///< features found (0 without words)
  std::size_t instances = 0;             ///< word instances in the file
  std::size_t alphabet_words = 0;        ///< words of the alphabet learned or reused (0 without words)
  bool words = false;                    ///< the file holds word instances
  std::optional<double> max_error;       ///< the residual layer's bound, metres, when there is one
  residual::LayerStats layer;            ///< what coding the layer did
  /// Per-point attributes kept in the file (formats/model.md §2.10) and how.
  std::vector<residual::AttributeField> attributes;
  /// Per-point attributes of the input the file does not keep (e.g. "intensity" with no
  /// residual layer, or with keep_attributes off), reported rather than dropped silently.
  std::vector<std::string> dropped_attributes;
  [[nodiscard]] double bits_per_point() const noexcept {
    return input_points ? 8.0 * static_cast<double>(bytes.size()) / static_cast<double>(input_points) : 0.0;
  }
};

/// Compresses one scan into a model file: learns an alphabet on it (or reuses
/// options.alphabet), models it and codes it as `options` say, exactly as
/// `lex3d compress SCAN -o OUT` with the same settings. An empty cloud gives a model of
/// an empty scan. Throws std::invalid_argument for invalid options or a cloud with a
/// non-finite point or a per-point array (intensity, ring, column) of the wrong length;
/// kBadData for an alphabet file that does not decode, or a target_bpp no layer fits.
[[nodiscard]] StatusOr<CompressResult> compress(const Cloud& cloud, const CompressOptions& options = {});

/// A decompressed scan.
struct DecompressResult {
  /// The decoded points (model frame, metres), its sensor pose (T_cloud_sensor) and,
  /// for georeferenced input, its georeference (true coordinates: origin + point).
  Cloud cloud;
  std::uint64_t input_points = 0;  ///< points of the scan the file was made from
  std::size_t instances = 0;       ///< word instances
  std::size_t alphabet_words = 0;  ///< words of the alphabet used
  bool residual_layer = false;     ///< the file has a residual layer (bounded error)
  bool references_alphabet = false;  ///< the file references an alphabet file (else embeds its alphabet)
  double decode_ms = 0.0;          ///< parsing the file (chunks, alphabet, instances)
  double reconstruct_ms = 0.0;     ///< placing the words and decoding the layer
};

/// Decodes a model file. `alphabet_file`: the alphabet file the model references (null
/// for a model that embeds its alphabet). kInvalidArgument when the model references an
/// alphabet and none (or another one) is given; kBadData for anything malformed,
/// truncated or corrupt, with the byte offset where it was found.
[[nodiscard]] StatusOr<DecompressResult> decompress(const std::vector<std::uint8_t>& model_file,
                                                    const std::vector<std::uint8_t>* alphabet_file = nullptr);

/// Settings of `learn_alphabet` (those of `lex3d learn`): LearnParams (model settings,
/// iterations, patience, seed, pruning) and an optional progress callback.
struct AlphabetOptions : LearnParams {
  /// Called after every candidate word (iteration, BIC, alphabet size); may be empty.
  std::function<void(const LearnProgress&)> progress;
};

/// A learned alphabet: its file and the learner's diagnostics.
struct AlphabetResult {
  std::vector<std::uint8_t> bytes;  ///< the alphabet file (formats/alphabet.md), for CompressOptions::alphabet
  /// The learner's result: the alphabet, one model per scan, the BIC at every iteration,
  /// accepted/rejected counts and timings (its `scans` is left empty).
  LearnResult learning;
};

/// Learns one alphabet for `clouds` (ruhnke2010 §III) and encodes its file, exactly as
/// `lex3d learn SCAN... -o ALPHABET`. Throws std::invalid_argument for invalid options,
/// no clouds, or a cloud with a non-finite point.
[[nodiscard]] AlphabetResult learn_alphabet(const std::vector<Cloud>& clouds, const AlphabetOptions& options);

/// Throws std::invalid_argument when `cloud` has a non-finite point or a per-point array
/// (intensity, ring, column) whose length is not the point count; `what` names the cloud
/// in the message ("cloud", "clouds[3]", ...).
void check_cloud(const Cloud& cloud, const std::string& what = "cloud");

}  // namespace lex3d

#pragma GCC visibility pop
