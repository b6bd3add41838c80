#pragma once
// Helpers for tests that build model files by hand.

#include "lex3d/codec/codec.hpp"
#include "lex3d/model/model.hpp"

namespace lex3d::test {

/// Gives `d` an embedded alphabet of one word without points and one instance of it: a
/// model with instances, whose file keeps the lowest format version its chunks need (a
/// model without instances is written as format 1.11, formats/model.md §2.1), while its
/// reconstruction, and so a residual layer's keep mask, stays empty.
inline void add_empty_word_instance(codec::ModelData& d) {
  Alphabet a;
  a.word_radius = 0.25;
  a.point_spacing = 0.025;
  a.descriptor_dim = 1;
  a.words.resize(1);
  a.words[0].descriptor = {0.5F};
  d.alphabet = a;
  d.alphabet_hash.reset();
  d.model.instances = {Instance{}};
}

}  // namespace lex3d::test
