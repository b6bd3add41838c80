#pragma once
// Shared by the libFuzzer targets (fuzz_model.cpp, fuzz_alphabet.cpp) and the corpus
// replay driver (corpus_replay.cpp): feed one input to the decoders and abort when a
// documented property fails (a crash or sanitizer report is caught by the tools anyway).
//
// Properties (formats/model.md §4, formats/alphabet.md §5):
// - a failure is kBadData (or kInvalidArgument for a referencing model decoded without
//   its alphabet file), with a one-line message and a byte offset inside the input;
// - a success is a consistent value: word ids below the alphabet size, finite poses and
//   points, and it encodes and decodes again to the same word ids;
// - inspect's chunk table lies inside the input;
// - a sequence file's scans are checked as model files with its alphabet;
// - a model with a residual layer (model.md §2.5-2.7) decodes to finite points, no more than
//   the reconstruction and the input point count allow, or fails like the codec does.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

#include "lex3d/codec/codec.hpp"
#include "lex3d/residual/residual.hpp"

namespace lex3d::fuzz {

[[noreturn]] inline void fail(const char* what, const std::string& detail) {
  std::fprintf(stderr, "fuzz property violated: %s: %s\n", what, detail.c_str());
  std::abort();
}

/// A tiny valid alphabet file, given as the external alphabet of referencing models
/// (the same alphabet as tests/codec/golden/tiny_alphabet_1.0.lex3da).
inline const std::vector<std::uint8_t>& external_alphabet() {
  static const std::vector<std::uint8_t> bytes = [] {
    Alphabet a;
    a.word_radius = 0.25;
    a.point_spacing = 0.025;
    a.descriptor_dim = 4;
    a.words.resize(3);
    a.words[0].points = {{0.0F, 0.0F, 0.0F}, {0.1F, 0.0F, 0.0F}, {0.0F, 0.1F, 0.0F}, {0.0F, 0.0F, -0.1F}};
    a.words[0].descriptor = {1.0F, -1.0F, 0.0F, 0.5F};
    a.words[1].points = {{0.05F, 0.05F, 0.05F}, {-0.2F, 0.0125F, 0.1F}, {0.0003F, -0.0003F, 0.2485F}};
    a.words[1].descriptor = {0.25F, -0.25F, 0.75F, -0.75F};
    a.words[2].descriptor = {0.0F, 0.001F, -0.999F, 0.3F};
    return codec::encode_alphabet(a);
  }();
  return bytes;
}

inline void check_status(const Status& s, std::size_t max_offset, bool allow_invalid_argument) {
  const bool code_ok = s.code() == ErrorCode::kBadData ||
                       (allow_invalid_argument && s.code() == ErrorCode::kInvalidArgument);
  if (!code_ok) fail("unexpected error code", s.to_string());
  if (s.message().empty() || s.to_string().find('\n') != std::string::npos) fail("message not one line", s.to_string());
  if (!s.offset() || *s.offset() > max_offset) fail("offset missing or past the input", s.to_string());
}

inline void check_alphabet_value(const Alphabet& a) {
  for (const auto& w : a.words) {
    if (w.descriptor.size() != static_cast<std::size_t>(a.descriptor_dim)) fail("descriptor size", "");
    for (const auto& p : w.points)
      if (!p.allFinite()) fail("non-finite word point", "");
    for (const float d : w.descriptor)
      if (!(d >= -1.0F && d <= 1.0F)) fail("descriptor value outside [-1, 1]", std::to_string(d));
  }
}

inline void check_residual(const codec::ModelData& d) {
  if (!d.residual) return;
  std::size_t placed = 0;  // reconstruction size before thinning: skip inputs that would take long
  for (const auto& inst : d.model.instances) placed += d.alphabet->words[inst.word].points.size();
  if (placed > 200000 || d.input_points > 2000000) return;
  const auto c = residual::decode_cloud(d);
  if (!c.ok()) {  // an offset in the layer's payload or, for an ATTR error, in the attributes'
    check_status(c.status(), std::max(d.residual->size(), d.attributes ? d.attributes->size() : std::size_t{0}), false);
    return;
  }
  if (c.value().size() > placed + d.input_points) fail("residual layer decoded more points than allowed", "");
  for (const auto& p : c.value().points)
    if (!p.allFinite()) fail("residual layer decoded a non-finite point", "");
}

inline void check_inspect(const std::vector<std::uint8_t>& bytes) {
  const auto info = codec::inspect(bytes);
  if (!info.ok()) {
    check_status(info.status(), bytes.size(), false);
    return;
  }
  for (const auto& c : info.value().chunks)
    if (c.offset + 16 > bytes.size() || c.length > bytes.size() - c.offset - 16) fail("inspect chunk past the end", c.type);
}

inline void check_model_bytes(const std::vector<std::uint8_t>& bytes, const std::vector<std::uint8_t>* external) {
  const auto r = codec::decode_model(bytes, external);
  const std::size_t max_offset = std::max(bytes.size(), external ? external->size() : std::size_t{0});
  if (!r.ok()) {
    check_status(r.status(), max_offset, external == nullptr);
    return;
  }
  const codec::ModelData& d = r.value();
  if (!d.alphabet) fail("decoded model without alphabet", "");
  check_alphabet_value(*d.alphabet);
  for (const auto& inst : d.model.instances) {
    if (inst.word >= d.alphabet->size()) fail("word id past the alphabet", std::to_string(inst.word));
    if (!inst.T_cloud_word.matrix().allFinite()) fail("non-finite instance pose", "");
  }
  check_residual(d);
  // Encodes again (coarsest steps, so every decoded value fits) and decodes alike.
  codec::ModelData again = d;
  again.alphabet_hash.reset();
  std::vector<std::uint8_t> re;
  try {
    re = codec::encode_model(again, codec::Quantization{0.1, 0.1, 0.1});
  } catch (const std::invalid_argument&) {
    return;  // a value at the very edge of the i32 range after f32 rounding
  }
  const auto r2 = codec::decode_model(re);
  if (!r2.ok()) fail("re-encoded model does not decode", r2.status().to_string());
  if (r2.value().model.instances.size() != d.model.instances.size()) fail("re-encoded instance count", "");
  for (std::size_t i = 0; i < d.model.instances.size(); ++i)
    if (r2.value().model.instances[i].word != d.model.instances[i].word) fail("re-encoded word id", std::to_string(i));
}

/// A sequence file (formats/sequence.md): its framing, then each scan as a model file
/// with the sequence's alphabet.
inline void check_sequence_bytes(const std::vector<std::uint8_t>& bytes) {
  const auto r = codec::decode_sequence(bytes);
  if (!r.ok()) {
    check_status(r.status(), bytes.size(), false);
    return;
  }
  for (const auto& m : r.value().model_files) check_model_bytes(m, &r.value().alphabet_file);
}

/// Everything the model fuzzer does with one input.
inline void check_model(const std::uint8_t* data, std::size_t size) {
  const std::vector<std::uint8_t> bytes(data, data + size);
  check_model_bytes(bytes, nullptr);
  check_model_bytes(bytes, &external_alphabet());
  check_sequence_bytes(bytes);
  check_inspect(bytes);
}

/// Everything the alphabet fuzzer does with one input.
inline void check_alphabet(const std::uint8_t* data, std::size_t size) {
  const std::vector<std::uint8_t> bytes(data, data + size);
  const auto r = codec::decode_alphabet(bytes);
  if (!r.ok()) {
    check_status(r.status(), bytes.size(), false);
  } else {
    check_alphabet_value(r.value());
    std::vector<std::uint8_t> re;
    bool encoded = true;
    try {
      re = codec::encode_alphabet(r.value(), codec::Quantization{0.1, 0.1, 0.1});
    } catch (const std::invalid_argument&) {
      encoded = false;
    }
    if (encoded) {
      const auto r2 = codec::decode_alphabet(re);
      if (!r2.ok()) fail("re-encoded alphabet does not decode", r2.status().to_string());
      if (r2.value().size() != r.value().size()) fail("re-encoded word count", "");
    }
  }
  check_inspect(bytes);
  // The alphabet as the external alphabet of a referencing model (hash computed here,
  // so the fuzzer reaches the external alphabet's decoder through decode_model too).
  codec::ModelData m;
  m.alphabet_hash = codec::alphabet_hash(bytes);
  const auto model = codec::encode_model(m);
  const auto rm = codec::decode_model(model, &bytes);
  if (!rm.ok()) check_status(rm.status(), std::max(bytes.size(), model.size()), false);
  if (rm.ok() != r.ok()) fail("external alphabet accepted differently", "");
}

}  // namespace lex3d::fuzz
