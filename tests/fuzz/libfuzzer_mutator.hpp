#pragma once
// libFuzzer custom mutator (include in exactly one file of a fuzz target): two thirds of
// the time a structure-aware mutation (fuzz_mutate.hpp) driven by libFuzzer's own byte
// mutator, so that mutated files keep valid CRCs and deflate streams; else a plain one.

#include <cstring>
#include <random>

#include "fuzz_mutate.hpp"

// The structure-aware mutation: the model/alphabet container's unless the target names
// another (define it before including this file, e.g. fuzz_place_db.cpp's mutate_place_db).
#ifndef LEX3D_FUZZ_MUTATE_STRUCTURE
#define LEX3D_FUZZ_MUTATE_STRUCTURE lex3d::fuzz::mutate_structure
#endif

extern "C" std::size_t LLVMFuzzerMutate(std::uint8_t* data, std::size_t size, std::size_t max_size);

extern "C" std::size_t LLVMFuzzerCustomMutator(std::uint8_t* data, std::size_t size, std::size_t max_size,
                                               unsigned int seed) {
  std::minstd_rand rng(seed);
  if (rng() % 3 != 0) {
    lex3d::fuzz::Bytes file(data, data + size);
    const auto mutate = [](lex3d::fuzz::Bytes& b) {
      if (b.empty()) b.push_back(0);
      const std::size_t n = b.size();
      b.resize(n + 64 + n / 4);
      b.resize(LLVMFuzzerMutate(b.data(), n, b.size()));
    };
    if (LEX3D_FUZZ_MUTATE_STRUCTURE(file, rng, mutate) && !file.empty() && file.size() <= max_size) {
      std::memcpy(data, file.data(), file.size());
      return file.size();
    }
  }
  return LLVMFuzzerMutate(data, size, max_size);
}
