#pragma once
/// \file
/// The lex3d model file and alphabet file (formats/model.md, formats/alphabet.md):
/// encoders and hardened decoders. Output is deterministic: the same input and options
/// give the same bytes. Decoders never crash on corrupt input; they return a Status
/// with a message and the byte offset of the problem.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/alphabet/alphabet.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/model/model.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::codec {

/// Quantisation steps; they are written into the files, so decoders need no options.
struct Quantization {
  /// Instance translations, metres; (0, 0.1]. Error per axis <= step / 2.
  double translation_m = 0.0005;
  /// Instance rotations (rotation-vector components), radians; (0, 0.1].
  double rotation_rad = 0.0002;
  /// Word points in the word frame, metres; (0, 0.1]. Error per axis <= step / 2.
  double word_point_m = 0.0005;
  void validate() const;
};

/// Instance steps scaled to the word radius δ: translations δ/32 (at most 0.1 m),
/// rotations 1/32 rad, word points 0.5 mm. A reconstructed point then moves by at most
/// √3/2 · (δ/32 + δ/32 + 0.5 mm) ≈ 0.054 δ (formats/model.md §3): with δ = 8 beam spacings
/// at the median range, under half a beam spacing there, and far below the words' own fit
/// error (against fixed 2 mm / 1 mrad steps: bench/README.md, "Model files").
/// δ <= 0 (no words): 2 mm / 1 mrad.
[[nodiscard]] Quantization quantization_for_word_radius(double word_radius);

/// Whether a residual payload is of the sweep coding, stored as an RESW chunk
/// (formats/model.md §2.6): its bytes 4..7 are 0xFF and its coding u32 is 1.
[[nodiscard]] bool is_sweep_layer(const std::vector<std::uint8_t>& payload);
/// The coding of a residual payload, which names its chunk: 0 the previous-point coding
/// (RESD, §2.5), else the coding u32 that a payload starting with it holds (its bytes
/// 4..7 are 0xFF): 1 the sweep coding (RESW, §2.6), 2 the voxel coding (RESV, §2.7), any
/// other value unknown.
[[nodiscard]] std::uint32_t layer_coding(const std::vector<std::uint8_t>& payload);

/// Everything a model file holds.
struct ModelData {
  std::uint64_t input_points = 0;             ///< points of the scan the model was made from
  Pose T_cloud_sensor = Pose::Identity();     ///< sensor pose in the model's frame (for ray casting)
  Model model;                                ///< instances
  /// The alphabet when embedded (flag bit 0); else nullopt and alphabet_hash names it.
  std::optional<Alphabet> alphabet;
  /// Content hash of the external alphabet file (FNV-1a 64 of its bytes) when referenced.
  std::optional<std::uint64_t> alphabet_hash;
  /// The residual layer's payload (formats/model.md §2.5-2.6; lex3d/residual/residual.hpp
  /// codes and decodes it), or nullopt for a words-only model. A model with one is
  /// written as format 1.1 (a RESD chunk) or, by its layer_coding, 1.2 (the sweep coding,
  /// an RESW chunk) or 1.3 (the voxel coding, an RESV chunk); one without as 1.0.
  std::optional<std::vector<std::uint8_t>> residual;
  /// Where the model's frame sits in a georeferenced frame (formats/model.md §2.8): the
  /// decoded points' true coordinates are origin + point. A model with one is written as
  /// format 1.5 (a GEOR chunk); Georeference::representation_error_m is not stored.
  std::optional<Georeference> georef;
  /// The point attributes of the decoded points (formats/model.md §2.10;
  /// lex3d/residual/attributes.hpp codes and decodes it), or nullopt. A model with one is
  /// written as format 1.6 (an ATTR chunk).
  std::optional<std::vector<std::uint8_t>> attributes;
  /// When and in which frame the scan was taken (Cloud::stamp), or nullopt: an optional
  /// `scan` chunk (formats/model.md §2.13), which needs no format version.
  std::optional<ScanStamp> stamp;
};

/// Encodes an alphabet file. Throws std::invalid_argument for an invalid `q` or alphabet
/// (a descriptor of the wrong length or with a value outside [-1, 1], a non-finite point or
/// one beyond 2^31 steps, a negative or non-finite radius or spacing).
[[nodiscard]] std::vector<std::uint8_t> encode_alphabet(const Alphabet& alphabet, const Quantization& q = {});
/// Decodes an alphabet file.
[[nodiscard]] StatusOr<Alphabet> decode_alphabet(const std::vector<std::uint8_t>& bytes);
/// The content hash a model file uses to reference an alphabet file (FNV-1a 64 of the
/// file's bytes; it detects a wrong or changed file, it is not a cryptographic hash).
[[nodiscard]] std::uint64_t alphabet_hash(const std::vector<std::uint8_t>& alphabet_file);

/// Encodes a model file; `data.alphabet` set embeds it, else `data.alphabet_hash` must be set.
/// Throws std::invalid_argument for an invalid `q`, neither alphabet nor hash, a word id beyond
/// the embedded alphabet, a pose that is not a finite rigid transform (rotation orthonormal
/// within 1e-6) or a translation beyond 2^31 steps.
[[nodiscard]] std::vector<std::uint8_t> encode_model(const ModelData& data, const Quantization& q = {});
/// Decodes a model file. A model that references an alphabet needs `external_alphabet_file`
/// (the alphabet file's bytes, checked against the stored hash); its alphabet is then decoded
/// into ModelData::alphabet. Without it such a model is not decoded: the Status has code
/// kInvalidArgument (the caller must supply the file); errors inside the external file carry
/// offsets in that file. A model that embeds its alphabet ignores `external_alphabet_file`.
/// Instance::feature is not stored and decodes as 0; the instance order is kept.
[[nodiscard]] StatusOr<ModelData> decode_model(const std::vector<std::uint8_t>& bytes,
                                               const std::vector<std::uint8_t>* external_alphabet_file = nullptr);

/// A sequence file (formats/sequence.md): the model files of a set of scans and the one
/// alphabet they share, in one file.
struct SequenceData {
  std::vector<std::uint8_t> alphabet_file;              ///< an alphabet file, byte for byte
  std::vector<std::vector<std::uint8_t>> model_files;   ///< model files referencing it, in scan order
  /// Each scan's name (its input's file stem), one a model file, or empty when the file keeps
  /// none (format 1.0). A name is 1 to 255 bytes with no '/', '\' or NUL, not "." or "..";
  /// names are unique (formats/sequence.md §2).
  std::vector<std::string> names;
};
/// Whether `name` may be a scan's name in a sequence file (see SequenceData::names).
[[nodiscard]] bool is_valid_scan_name(const std::string& name);
/// Whether `bytes` start with the sequence file's magic.
[[nodiscard]] bool is_sequence_file(const std::vector<std::uint8_t>& bytes);
/// Encodes a sequence file (1.1 with the scans' names, else 1.0). Throws
/// std::invalid_argument when the alphabet file is invalid, a model file does not decode as
/// a model referencing that alphabet, or the names are not one valid, unique name a model.
[[nodiscard]] std::vector<std::uint8_t> encode_sequence(const SequenceData& data);
/// Decodes a sequence file's framing and its alphabet; each model file is then decoded
/// with `decode_model(model_files[i], &alphabet_file)`.
[[nodiscard]] StatusOr<SequenceData> decode_sequence(const std::vector<std::uint8_t>& bytes);

/// What `lex3d info` shows of a model, alphabet or sequence file.
struct ChunkInfo {
  std::string type;          ///< four characters
  std::uint64_t offset = 0;  ///< of the chunk header
  std::uint64_t length = 0;  ///< payload bytes
  bool crc_ok = false;
};
struct FileInfo {
  std::string kind;  ///< "model", "alphabet" or "sequence"
  int major = 0;
  int minor = 0;
  std::uint32_t flags = 0;
  bool header_crc_ok = false;  ///< the header's own CRC (bytes 0..15)
  std::vector<ChunkInfo> chunks;
  std::uint64_t file_bytes = 0;
  /// A model's instance steps (its MHDR chunk), when that chunk is intact.
  std::optional<double> translation_step_m, rotation_step_rad;
  /// An alphabet's word radius, word-point spacing and word-point step (its AHDR
  /// chunk), when that chunk is intact.
  std::optional<double> word_radius_m, point_spacing_m, word_point_step_m;
};
/// Reads the header and chunk table without decoding payloads; fails only when the
/// header or the chunk framing is unreadable (a CRC mismatch is reported, not fatal).
[[nodiscard]] StatusOr<FileInfo> inspect(const std::vector<std::uint8_t>& bytes);

}  // namespace lex3d::codec

#pragma GCC visibility pop
