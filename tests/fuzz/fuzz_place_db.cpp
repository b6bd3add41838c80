// libFuzzer target: the place database loader (PlaceDatabase::load, read_scan, retrieve,
// query, save). Seeds: tests/fuzz/readers/placedb/. See tests/fuzz/CMakeLists.txt.
#include <cstring>
#include <random>

#include "fuzz_place_db.hpp"

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
    if (lex3d::fuzz::mutate_place_db(file, rng, mutate) && !file.empty() && file.size() <= max_size) {
      std::memcpy(data, file.data(), file.size());
      return file.size();
    }
  }
  return LLVMFuzzerMutate(data, size, max_size);
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lex3d::fuzz::check_place_db(data, size);
  return 0;
}
