#pragma once
/// \file
/// How one scan becomes a model file (formats/model.md): the choices `lex3d compress`
/// offers (words, a residual layer of a fixed bound or a bit budget, the layer's
/// codings, quantisation steps) and the coder that applies them with one alphabet to
/// many scans. `lex3d::compress` (lex3d/lex3d.hpp) and the `lex3d compress` command
/// both code through ScanCoder, so they write the same bytes for the same settings.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/codec/codec.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/model/model.hpp"
#include "lex3d/residual/attributes.hpp"
#include "lex3d/residual/residual.hpp"
#include "lex3d/residual/sensor_profile.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Whether a model file holds instances of the alphabet's words.
enum class WordsMode : std::uint8_t {
  kDefault,  ///< off with a residual layer, on without one
  kOn,       ///< words, plus the layer (when there is one) for what they do not explain
  kOff,      ///< every point in the residual layer, no alphabet (needs a layer)
  kAuto,     ///< code both forms and keep the smaller file (needs a layer)
};

/// Which residual-layer codings the encoder tries (formats/model.md §2.5-2.8).
enum class LayerCoding : std::uint8_t {
  kAuto,       ///< all of them, keeping the smallest
  kSpherical,  ///< the sensor-centred spherical codings only
  kVoxel,      ///< the voxel (octree) coding only
  kLaser,      ///< the sensor-geometry coding (spherical where the lasers are unknown)
  kAcquisition,  ///< the acquisition-order coding (spherical where the points carry no rising times)
  kLattice,      ///< the lattice coding (spherical where the points lie on no lattice)
};

/// How a scan is coded. Defaults: words only, no residual layer (as `lex3d compress`).
struct CodingOptions {
  /// Residual-layer bound E, metres, in [residual::kMinMaxError, residual::kMaxMaxError]:
  /// every input point has a decoded point within E and vice versa. nullopt: no bound
  /// given (words only, unless target_bpp is set).
  std::optional<double> max_error;
  /// Bits per input point the file should fit, in [1e-3, 1e3]; the layer then takes the
  /// smallest E that fits. 0: off. Not together with max_error.
  double target_bpp = 0.0;
  /// Words or not (WordsMode).
  WordsMode words = WordsMode::kDefault;
  /// Residual layer: skip an input point a point decoded before it explains within E
  /// (false, the default) or give every input point its own decoded point (true).
  bool keep_all_points = false;
  /// Residual-layer codings tried.
  LayerCoding layer_coding = LayerCoding::kAuto;
  /// Sensor-rate encoding (residual::LayerOptions::fast, and AttributeOptions::fast for the
  /// attributes): fewer codings tried; files a little larger.
  bool fast = false;
  /// The mean-squared-error objective (residual::LayerOptions::mse): the fewest bits for
  /// the mean squared error within the bound, rather than the fewest bits within it.
  bool mse = false;
  /// Instance steps, metres and radians, each 0 (derived from the alphabet's word radius,
  /// codec::quantization_for_word_radius) or in [1e-6, 0.1].
  codec::Quantization quantization{0.0, 0.0, 0.0005};
  /// Worker threads, [1, 64]; the bytes do not depend on it.
  int threads = 2;
  /// Per-point attributes (intensity, ring, time, colour) kept with a residual layer
  /// (formats/model.md §2.10): which, and how (intensity lossless by default).
  bool keep_attributes = true;
  residual::AttributeOptions attributes;

  /// The scan's laser table as its user knows it (formats/sensor_profile.md): the
  /// sensor-geometry coding takes every point's laser and column from it
  /// (residual::apply_sensor_profile) instead of estimating them; a scan whose points do not
  /// fit it is kBadData. Needs a residual layer. The input's own fields (a ring field
  /// included) are kept as they are.
  std::optional<residual::SensorProfile> sensor_profile;

  /// With a shared alphabet (referenced by hash), a file that keeps no instance (the layer
  /// alone was smaller, `WordsMode::kAuto`) embeds an empty alphabet and decodes without the
  /// alphabet file. Set this for models that go into a sequence file, which must all reference
  /// the sequence's alphabet.
  bool layer_only_references_alphabet = false;

  /// Throws std::invalid_argument naming the option and its allowed values.
  void validate() const;
  /// A residual layer is coded (max_error or target_bpp given).
  [[nodiscard]] bool layered() const noexcept { return max_error.has_value() || target_bpp > 0.0; }
  /// `words` with kDefault resolved.
  [[nodiscard]] WordsMode words_mode() const noexcept;
  /// The alphabet's words are used (words_mode() is not kOff).
  [[nodiscard]] bool uses_words() const noexcept { return words_mode() != WordsMode::kOff; }
  /// The residual layer's options these settings stand for.
  [[nodiscard]] residual::LayerOptions layer_options() const;
};

/// One scan's model file and how it was coded.
struct CodedScan {
  std::vector<std::uint8_t> bytes;   ///< the model file (formats/model.md)
  bool words = true;                 ///< it holds instances of the alphabet
  std::optional<double> max_error;   ///< the residual layer's bound, metres, when it has one
  residual::LayerStats layer;        ///< what coding the layer did (zeros without one)
  std::size_t instances = 0;         ///< instances in the file
  std::vector<residual::AttributeField> attributes;  ///< fields kept (an ATTR chunk)
  std::vector<std::string> dropped;                  ///< fields the input has and the file does not keep
  std::optional<residual::ProfileFit> profile_fit;   ///< how the points fit CodingOptions::sensor_profile
};

/// The per-point fields `cloud` has, by name ("ring", "intensity", "time", "rgb").
[[nodiscard]] std::vector<std::string> attribute_fields(const Cloud& cloud);

/// What modelling a scan with a known alphabet did.
struct ScanModelStats {
  std::size_t features = 0;         ///< interest + coverage features
  FeatureTimings feature_ms;        ///< feature extraction stages
  double neighbourhoods_ms = 0.0;   ///< σ and the points near each feature
  EncodeTimings encode_ms;          ///< frames, word choice, ICP, pruning
};

/// Codes scans with one alphabet: derives the instance steps from the alphabet, the
/// alphabet exactly as a decoder will see it (for the residual layer), and whether the
/// alphabet is embedded in each model file or referenced by its content hash.
class ScanCoder {
 public:
  /// `alphabet`: the words the models use (empty when options.uses_words() is false).
  /// The models embed the alphabet, or reference it by content hash when
  /// `reference_alphabet` is set (its file, encoded with the coder's steps, is then
  /// alphabet_file()) or `reused_file` is given: an alphabet file that decodes to
  /// `alphabet`, which the models then reference. Throws std::invalid_argument for
  /// invalid options.
  ScanCoder(Alphabet alphabet, const CodingOptions& options, bool reference_alphabet = false,
            std::vector<std::uint8_t> reused_file = {});

  /// Codes `cloud` with `model` (its instances of the alphabet; ignored without words):
  /// words only, or words and/or a residual layer, keeping the smallest allowed form.
  /// kBadData when no layer fits options.target_bpp, or for an attribute the scan has
  /// that cannot be coded (a non-finite value; the message names the field).
  [[nodiscard]] StatusOr<CodedScan> code(const Cloud& cloud, const Model& model, int threads) const;

  /// Models `cloud` with the alphabet (prepare_scan, then encode_scan, pruned when
  /// params.prune) on `threads` threads; an empty model when the options use no words.
  /// `stats`: where the time went, when given.
  [[nodiscard]] Model model_scan(const Cloud& cloud, const LearnParams& params, int threads,
                                 ScanModelStats* stats = nullptr) const;

  [[nodiscard]] const Alphabet& alphabet() const noexcept { return alphabet_; }
  /// The instance steps the files are written with.
  [[nodiscard]] const codec::Quantization& quantization() const noexcept { return quantization_; }
  /// The alphabet file the models reference (empty: embedded).
  [[nodiscard]] const std::vector<std::uint8_t>& alphabet_file() const noexcept { return alphabet_file_; }
  [[nodiscard]] bool embeds_alphabet() const noexcept { return alphabet_file_.empty(); }

 private:
  Alphabet alphabet_;
  CodingOptions options_;
  codec::Quantization quantization_;
  std::vector<std::uint8_t> alphabet_file_;
  std::uint64_t hash_ = 0;
  std::optional<Alphabet> decoder_alphabet_;
};

}  // namespace lex3d

#pragma GCC visibility pop
